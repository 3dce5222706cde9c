"""An ONNX network on the CPU through onnxruntime: the one runtime perception's models use.

`OnnxNet(model, threads)` loads the model once (all graph optimisations, sequential
execution, `threads` intra-op threads: perception shares two cores with the sim and the
controller, and a forward split over threads waits for the slowest); `run(blob)` gives
every output, in the model's order; `metadata` the model's custom metadata (an
ultralytics export's `names`). onnxruntime's forward of the shipped segmenter is 3-4×
OpenCV DNN's on the same file and thread budget, with the same logits (`dume bench
perception`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import onnxruntime as ort
from numpy.typing import NDArray


class OnnxError(ValueError):
    """A model that cannot be loaded or run: why."""


class OnnxNet:
    """One loaded ONNX model (see the module docstring)."""

    def __init__(self, model: Path | str, threads: int | None = None) -> None:
        options = ort.SessionOptions()
        options.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
        options.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
        options.inter_op_num_threads = 1
        if threads is not None:
            options.intra_op_num_threads = threads
        options.log_severity_level = 3  # errors only: no start-up chatter in the logs
        try:
            self.session = ort.InferenceSession(
                str(model), options, providers=["CPUExecutionProvider"]
            )
        except Exception as exc:  # onnxruntime raises its own (untyped) errors
            raise OnnxError(f"cannot load {model}: {exc}") from exc
        self.input = self.session.get_inputs()[0].name
        self.outputs = [o.name for o in self.session.get_outputs()]

    @property
    def metadata(self) -> dict[str, str]:
        return dict(self.session.get_modelmeta().custom_metadata_map)

    def run(self, blob: NDArray[np.float32]) -> list[NDArray[np.float32]]:
        try:
            outs = self.session.run(self.outputs, {self.input: blob})
        except Exception as exc:
            raise OnnxError(f"forward failed on a {blob.shape} input: {exc}") from exc
        return [np.asarray(o, dtype=np.float32) for o in outs]
