"""The YOLOv8-seg decoder: known tensors give known boxes, classes, scores and masks; a
synthetic ONNX model of an ultralytics export's shapes runs through onnxruntime."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.perception import yolo
from services.perception.segmenter import SegmenterError

NAMES = ["bottle", "person"]
SIZE, PROTO = 64, 16  # network input and prototype side, px
SYNTHETIC = Path(__file__).parent / "data" / "yolov8_seg_synthetic.onnx"


def _protos() -> np.ndarray:
    """Prototype 0: all ones; prototype 1: +1 on the left half, -1 on the right."""
    p = np.zeros((1, 32, PROTO, PROTO), np.float32)
    p[0, 0] = 1.0
    p[0, 1, :, : PROTO // 2], p[0, 1, :, PROTO // 2 :] = 1.0, -1.0
    return p


def _candidate(
    box: tuple[float, float, float, float], scores: list[float], coeffs: dict[int, float]
) -> np.ndarray:
    row = np.zeros(4 + len(NAMES) + 32, np.float32)
    row[:4], row[4 : 4 + len(NAMES)] = box, scores
    for k, v in coeffs.items():
        row[4 + len(NAMES) + k] = v
    return row


def _output0() -> np.ndarray:
    rows = [
        _candidate((20, 20, 16, 16), [0.9, 0.1], {0: 10.0}),  # a bottle filling its box
        _candidate((21, 20, 16, 16), [0.8, 0.0], {0: 10.0}),  # its duplicate: NMS drops it
        _candidate((22, 22, 16, 16), [0.0, 0.7], {1: 10.0}),  # a person: another class, kept
        _candidate((50, 50, 8, 8), [0.1, 0.05], {0: 10.0}),  # under the confidence threshold
    ]
    return np.stack(rows, axis=1)[None]  # (1, 4 + nc + 32, N)


def _identity_box(h: int = SIZE, w: int = SIZE) -> yolo.Letterbox:
    return yolo.Letterbox(1.0, 0, 0, (h, w), (SIZE, SIZE))


def test_known_tensors_decode_to_known_instances() -> None:
    found = yolo.decode(_output0(), _protos(), NAMES, _identity_box())
    assert [(i.class_name, round(i.score, 3)) for i in found] == [("bottle", 0.9), ("person", 0.7)]
    bottle, person = found
    assert bottle.bbox == (12, 12, 28, 28)
    box = np.zeros((SIZE, SIZE), bool)
    box[12:28, 12:28] = True
    assert not (bottle.mask & ~box).any()  # never outside its box
    assert np.count_nonzero(bottle.mask & box) / box.sum() > 0.85
    # The person's prototype is the image's left half (u < 32), cut to its box 14..30.
    assert person.bbox == (14, 14, 30, 30)
    us = np.nonzero(person.mask)[1]
    assert us.min() == 14 and us.max() <= 31


def test_nothing_above_the_threshold_decodes_to_nothing() -> None:
    assert yolo.decode(_output0(), _protos(), NAMES, _identity_box(), conf_threshold=0.95) == []


def test_letterboxed_images_map_back_to_their_own_pixels() -> None:
    rgb = np.zeros((48, 64, 3), np.uint8)
    blob, box = yolo.letterbox(rgb, SIZE)
    assert blob.shape == (1, 3, SIZE, SIZE) and (box.pad_x, box.pad_y, box.scale) == (0, 8, 1.0)
    found = yolo.decode(_output0(), _protos(), NAMES, box)
    bottle = found[0]
    assert bottle.mask.shape == (48, 64)
    assert bottle.bbox == (12, 4, 28, 20)  # 8 px of padding above


def test_wrong_shapes_are_refused_with_the_shapes() -> None:
    with pytest.raises(SegmenterError, match="output0"):
        yolo.decode(np.zeros((1, 10, 4), np.float32), _protos(), NAMES, _identity_box())
    with pytest.raises(SegmenterError, match="prototypes"):
        yolo.decode(_output0(), np.zeros((1, 8, 4, 4), np.float32), NAMES, _identity_box())


def build_synthetic_model(path: Path) -> None:
    """An ONNX graph with an ultralytics YOLOv8-seg export's inputs and outputs whose
    outputs are the known tensors above (plus 0 × the input, so they depend on it)."""
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    out0, protos = _output0(), _protos()
    nodes = [
        helper.make_node("ReduceMean", ["images"], ["mean"], axes=[1, 2, 3], keepdims=0),
        helper.make_node("Mul", ["mean", "zero"], ["nil"]),
        helper.make_node("Add", ["c0", "nil"], ["output0"]),
        helper.make_node("Add", ["c1", "nil"], ["output1"]),
    ]
    graph = helper.make_graph(
        nodes,
        "yolov8_seg_synthetic",
        [helper.make_tensor_value_info("images", TensorProto.FLOAT, [1, 3, SIZE, SIZE])],
        [
            helper.make_tensor_value_info("output0", TensorProto.FLOAT, list(out0.shape)),
            helper.make_tensor_value_info("output1", TensorProto.FLOAT, list(protos.shape)),
        ],
        initializer=[
            numpy_helper.from_array(out0, "c0"),
            numpy_helper.from_array(protos, "c1"),
            numpy_helper.from_array(np.zeros(1, np.float32), "zero"),
        ],
    )
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    helper.set_model_props(model, {"names": str(dict(enumerate(NAMES)))})
    onnx.checker.check_model(model)
    onnx.save(model, str(path))


def test_the_shipped_synthetic_model_is_what_the_builder_makes(tmp_path: Path) -> None:
    build_synthetic_model(tmp_path / "m.onnx")
    assert (tmp_path / "m.onnx").read_bytes() == SYNTHETIC.read_bytes()


def test_a_synthetic_export_runs_through_onnxruntime() -> None:
    seg = yolo.YoloSegmenter(SYNTHETIC, names=NAMES, input_size=SIZE)
    found = seg.segment(np.full((SIZE, SIZE, 3), 80, np.uint8))
    assert [(i.class_name, round(i.score, 3)) for i in found] == [("bottle", 0.9), ("person", 0.7)]
    assert found[0].bbox == (12, 12, 28, 28)


def test_class_names_come_from_the_models_metadata() -> None:
    seg = yolo.YoloSegmenter(SYNTHETIC, input_size=SIZE)
    assert seg.names == NAMES
