"""The robot's RGB-D cameras: one offscreen renderer, two or three passes per capture.

`CameraRig(model, width, height)` holds one `mujoco.Renderer` for its resolution (every
robot camera shares it) with shadows, reflections and multisampling off. A capture
updates the scene once from the camera and renders RGB and depth (`capture_frame`) and,
when someone needs them, the segmentation labels (`capture_labels`; `capture` does all):
- depth is MuJoCo's linearised z-buffer, i.e. the distance along the optical axis (not
  along the pixel's ray; `tests/unit/test_cameras.py` checks both against geometry),
  float32 metres, 0 where nothing is drawn (the far plane); with `depth_noise`, as the
  stereo sensor measures it (`services.sim.sensors.DepthNoise`);
- segmentation becomes instance labels through `scene.segmentation_ids` (artifacts,
  people and obstacles of the world, the robot; 0 for the floor and the sky);
- intrinsics are `common.robot.intrinsics` at the rig's resolution; `T_base_camera`
  (OpenCV optical frame) comes from the same kinematics the image shows. The base's
  pose in the world (`base_pose`) is the sim's truth: it is not in the frame.
`render_ms` keeps each camera's last capture time; `render_s` and `captures` the wall
seconds spent and the captures made, per camera, since the rig was made.
"""

from __future__ import annotations

import dataclasses
import time

import mujoco
import numpy as np

from common import robot
from common.geometry import FloatArray, inv_T, make_T
from common.messages import to_wire
from common.messages.sim import CameraFrame, SegmentationTruth
from common.messages.world import WorldDescription
from services.sim import scene
from services.sim.sensors import DepthNoise

_MJ_CAMERA_TO_OPTICAL = np.diag([1.0, -1.0, -1.0])  # MuJoCo cameras look down -z, y up


def _row_major(T: FloatArray) -> tuple[float, ...]:
    return tuple(T.ravel().tolist())


class CameraRig:
    """Renders the robot's cameras at one resolution from a model's `MjData`."""

    def __init__(
        self,
        model: mujoco.MjModel,
        width: int = 320,
        height: int = 240,
        world: WorldDescription | None = None,
        depth_noise: DepthNoise | None = None,
    ) -> None:
        self.model = model
        self.width, self.height = width, height
        self.depth_noise = depth_noise
        self.renderer = mujoco.Renderer(model, height, width)
        flags = self.renderer.scene.flags
        for flag in (mujoco.mjtRndFlag.mjRND_SHADOW, mujoco.mjtRndFlag.mjRND_REFLECTION):
            flags[flag] = False
        self.table = scene.segmentation_ids(model, world)
        self.instances = {k: v for k, v in self.table.labels.items() if k != scene.BACKGROUND_LABEL}
        self.mounts = {name: self.mount(name, width, height) for name in robot.CAMERA_MOUNTS}
        self._base = model.body(robot.BASE_FRAME).id
        self._far = float(model.vis.map.zfar * model.stat.extent)
        self.render_ms: dict[str, float] = {}
        self.render_s: dict[str, float] = {}
        self.captures: dict[str, int] = {}

    def intrinsics(self, camera: str) -> tuple[float, float, float, float]:
        """(fx, fy, cx, cy) in pixels of `camera` at this rig's resolution."""
        return robot.intrinsics(self._mount(camera))

    @staticmethod
    def mount(camera: str, width: int, height: int) -> robot.CameraMount:
        """`camera`'s mount rendered at width × height (KeyError: no such camera)."""
        if camera not in robot.CAMERA_MOUNTS:
            raise KeyError(f"no camera {camera!r}; the robot has {sorted(robot.CAMERA_MOUNTS)}")
        return dataclasses.replace(robot.CAMERA_MOUNTS[camera], width=width, height=height)

    def capture(
        self, data: mujoco.MjData, camera: str, stamp_ns: int
    ) -> tuple[CameraFrame, SegmentationTruth]:
        """RGB-D and instance labels of `camera` as `data` stands now, stamped `stamp_ns`."""
        frame = self.capture_frame(data, camera, stamp_ns)
        return frame, self.capture_labels(camera, stamp_ns)

    def capture_frame(self, data: mujoco.MjData, camera: str, stamp_ns: int) -> CameraFrame:
        """RGB-D of `camera` as `data` stands now (two passes; `capture_labels` right after
        renders the third from the same scene)."""
        mount = self._mount(camera)
        t0 = time.perf_counter()
        r = self.renderer
        r.update_scene(data, camera=camera)
        rgb = r.render()
        r.enable_depth_rendering()
        depth = r.render()
        r.disable_depth_rendering()
        depth[depth >= self._far * (1.0 - 1e-4)] = 0.0
        if self.depth_noise is not None:
            depth = self.depth_noise.apply(depth, camera, stamp_ns)
        self._spent(camera, t0, capture=True)

        cam = self.model.camera(camera).id
        T_world_camera = make_T(
            data.cam_xmat[cam].reshape(3, 3) @ _MJ_CAMERA_TO_OPTICAL, data.cam_xpos[cam]
        )
        T_world_base = self.base_pose(data)
        fx, fy, cx, cy = robot.intrinsics(mount)
        return CameraFrame(
            stamp_ns=stamp_ns,
            camera=camera,
            width=self.width,
            height=self.height,
            fx=fx,
            fy=fy,
            cx=cx,
            cy=cy,
            rgb=to_wire(rgb),
            depth=to_wire(depth.astype(np.float32, copy=False)),
            T_base_camera=_row_major(inv_T(T_world_base) @ T_world_camera),
        )

    def base_pose(self, data: mujoco.MjData) -> FloatArray:
        """T_world_base (4×4) as the sim has it (truth: training labels and tests)."""
        return make_T(data.xmat[self._base].reshape(3, 3), data.xpos[self._base])

    def capture_labels(self, camera: str, stamp_ns: int) -> SegmentationTruth:
        """The instance labels of the scene `capture_frame` last set up (for `camera`)."""
        t0 = time.perf_counter()
        r = self.renderer
        r.enable_segmentation_rendering()
        labels = scene.label_image(r.render(), self.table)
        r.disable_segmentation_rendering()
        self._spent(camera, t0, capture=False)
        return SegmentationTruth(
            stamp_ns=stamp_ns, camera=camera, labels=to_wire(labels), instances=self.instances
        )

    def _spent(self, camera: str, t0: float, capture: bool) -> None:
        """Book a pass's wall time: a capture starts the camera's `render_ms` afresh,
        its labels add to it."""
        spent = time.perf_counter() - t0
        if capture:
            self.render_ms[camera] = 0.0
            self.captures[camera] = self.captures.get(camera, 0) + 1
        self.render_ms[camera] += spent * 1e3
        self.render_s[camera] = self.render_s.get(camera, 0.0) + spent

    def close(self) -> None:
        """Free the renderer's GL context."""
        self.renderer.close()

    def _mount(self, camera: str) -> robot.CameraMount:
        if camera not in self.mounts:
            raise KeyError(f"no camera {camera!r}; the robot has {sorted(self.mounts)}")
        return self.mounts[camera]
