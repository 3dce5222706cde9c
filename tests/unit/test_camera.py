"""`common.camera`: one pinhole camera for perception, navigation and the map.

The regression tests hold verbatim copies of the three depth-to-points functions (and the
two world-to-pixel tests) that `common.camera` replaced (perception's `backproject`,
navigation's `depth_points` and `seen_through`, the map's `depth_points_world` and
`looks_at`, as of commit dce4c37) and check that the shared code gives their callers the
same points, in the same order, with the same filtering, on synthetic depth images full
of edge cases (no return, NaN, ±inf, negative, near, far, masked, strides that do not
divide the image, crops).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from numpy.typing import NDArray

from common.camera import PinholeCamera, backproject, valid_depth
from common.geometry import FloatArray, inv_T, make_T, rot_x, rot_y, rot_z, transform_points
from common.robot_description import R_FORWARD_OPTICAL
from services.navigation.depth import DepthParams, seen_through
from services.navigation.grid import Grid
from services.semantic_map.looks import looks_at, sees_over

H, W = 61, 83  # odd sizes: strides 2, 3, 4 and 5 do not divide them
FX, FY, CX, CY = 70.5, 68.25, (W - 1) / 2 + 1.5, (H - 1) / 2 - 2.0
#: A camera 0.5 m up at (1, 2), facing 40° left of +x, pitched 20° down and rolled 5°.
T_WORLD_CAMERA = make_T(
    rot_z(math.radians(40)) @ rot_y(math.radians(20)) @ rot_x(math.radians(5)) @ R_FORWARD_OPTICAL,
    (1.0, 2.0, 0.5),
)


def _depth(seed: int = 0) -> NDArray[np.float32]:
    """A float32 depth image (H, W) with every kind of pixel the filters tell apart."""
    rng = np.random.default_rng(seed)
    d = rng.uniform(0.01, 8.0, (H, W)).astype(np.float32)
    flat = d.reshape(-1)
    picks = rng.permutation(flat.size)
    specials = [0.0, np.nan, np.inf, -np.inf, -1.0, 0.05, 4.0, 6.0, 0.03, 1e-6]
    for k, value in enumerate(specials):
        flat[picks[k * 40 : (k + 1) * 40]] = value
    return d


def _camera(depth: NDArray[np.float32] | None = None) -> PinholeCamera:
    return PinholeCamera(FX, FY, CX, CY, T_WORLD_CAMERA, depth)


# -- the replaced code, verbatim but for names (its camera types and parameters inlined) ----


def _old_perception_backproject(
    depth: NDArray[np.floating], mask: NDArray[np.bool_] | None, origin: tuple[int, int]
) -> FloatArray:
    d = np.asarray(depth, dtype=np.float64)
    valid = np.isfinite(d) & (d > 0.0)
    if mask is not None:
        valid &= mask.astype(bool)
    v, u = np.nonzero(valid)
    uv = np.atleast_2d(np.asarray(np.column_stack([u + origin[0], v + origin[1]]), dtype=float))
    z = np.asarray(d[v, u], dtype=float).reshape(-1)
    return np.column_stack([(uv[:, 0] - CX) / FX * z, (uv[:, 1] - CY) / FY * z, z])


def _old_nav_depth_points(depth: NDArray[np.float32], p: DepthParams) -> FloatArray:
    d = depth[:: p.stride, :: p.stride].astype(np.float64)
    v, u = np.mgrid[0 : depth.shape[0] : p.stride, 0 : depth.shape[1] : p.stride]
    ok = (d > 0) & (d < p.max_range_m) & np.isfinite(d)
    z = d[ok]
    pts = np.stack([(u[ok] - CX) / FX * z, (v[ok] - CY) / FY * z, z], axis=1)
    R, t = T_WORLD_CAMERA[:3, :3], T_WORLD_CAMERA[:3, 3]
    out: FloatArray = pts @ R.T + t
    return out


def _old_map_depth_points_world(
    depth: NDArray[np.float32],
    stride: int = 4,
    exclude: NDArray[np.bool_] | None = None,
    max_range_m: float = 6.0,
) -> FloatArray:
    d = depth[::stride, ::stride].astype(float)
    v, u = np.mgrid[0 : depth.shape[0] : stride, 0 : depth.shape[1] : stride]
    keep = (d > 0.05) & (d < max_range_m)
    if exclude is not None:
        keep &= ~exclude[::stride, ::stride]
    d, u, v = d[keep], u[keep], v[keep]
    pc = np.stack([(u - CX) * d / FX, (v - CY) * d / FY, d, np.ones_like(d)])
    out: FloatArray = (T_WORLD_CAMERA @ pc)[:3].T
    return out


def _old_seen_through(
    depth: NDArray[np.float32], grid: Grid, iy: NDArray[np.int64], ix: NDArray[np.int64]
) -> NDArray[np.bool_]:
    p = DepthParams()
    if not len(iy):
        return np.zeros(0, dtype=bool)
    xy = grid.centres(np.stack([iy, ix], axis=1))
    T_cw = np.linalg.inv(T_WORLD_CAMERA)
    h, w = depth.shape
    through = np.ones(len(iy), dtype=bool)
    for height in (0.15, 0.5):
        pw = np.column_stack([xy, np.full(len(xy), height)])
        pc = pw @ T_cw[:3, :3].T + T_cw[:3, 3]
        z = pc[:, 2]
        zs = np.where(z > 0.05, z, 1.0)
        u = np.rint(FX * pc[:, 0] / zs + CX).astype(np.int64)
        v = np.rint(FY * pc[:, 1] / zs + CY).astype(np.int64)
        visible = (z > 0.05) & (u >= 0) & (u < w) & (v >= 0) & (v < h)
        measured = np.zeros(len(iy))
        measured[visible] = depth[v[visible], u[visible]]
        through &= visible & (measured > z + p.see_through_m)
    return through


def _old_looks_at(
    depth: NDArray[np.float32],
    p_world: FloatArray,
    max_range_m: float,
    margin_px: int = 8,
    occluder_m: float = 0.15,
) -> bool:
    p = inv_T(T_WORLD_CAMERA) @ np.append(np.asarray(p_world, float), 1.0)
    z = float(p[2])
    if z < 0.2 or float(np.linalg.norm(p[:3])) > max_range_m:
        return False
    u = FX * p[0] / z + CX
    v = FY * p[1] / z + CY
    if not (margin_px <= u < W - margin_px and margin_px <= v < H - margin_px):
        return False
    iu, iv = round(u), round(v)
    patch = depth[max(iv - 2, 0) : iv + 3, max(iu - 2, 0) : iu + 3]
    valid = patch[patch > 0]
    if valid.size == 0:
        return True
    return float(np.median(valid)) >= z - occluder_m


# -- regression: the callers' points and decisions are those of the replaced code ----------


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_perception_points_are_the_old_backprojections_bit_for_bit(seed: int) -> None:
    depth = _depth(seed)
    mask = np.random.default_rng(seed + 10).random((H, W)) < 0.6
    cam = _camera()
    for m in (None, mask):
        new = backproject(depth, cam, mask=m)
        np.testing.assert_array_equal(new, _old_perception_backproject(depth, m, (0, 0)))
    # a crop at its place in the image (how perception measures one instance)
    u0, v0, u1, v1 = 11, 7, 60, 50
    crop, crop_mask = depth[v0:v1, u0:u1], mask[v0:v1, u0:u1]
    new = backproject(crop, cam, mask=crop_mask, origin=(u0, v0))
    np.testing.assert_array_equal(new, _old_perception_backproject(crop, crop_mask, (u0, v0)))
    # float64 depth (perception's tests and benches) gives the same points as float32
    np.testing.assert_array_equal(backproject(depth.astype(np.float64), cam, mask=mask),
                                  backproject(depth, cam, mask=mask))  # fmt: skip


@pytest.mark.parametrize("stride", [1, 2, 3, 4, 5])
@pytest.mark.parametrize("max_range_m", [4.0, 2.5])
def test_navigation_points_are_the_old_depth_points_bit_for_bit(
    stride: int, max_range_m: float
) -> None:
    depth = _depth(stride)
    p = DepthParams(stride=stride, max_range_m=max_range_m)
    new = _camera(depth).points_world(stride=p.stride, max_depth_m=p.max_range_m)
    np.testing.assert_array_equal(new, _old_nav_depth_points(depth, p))


@pytest.mark.parametrize("stride", [1, 3, 4])
def test_map_points_are_the_old_depth_points_world(stride: int) -> None:
    depth = _depth(stride + 5)
    exclude = np.zeros((H, W), bool)
    exclude[10:30, 20:45] = True
    for ex in (None, exclude):
        mask = None if ex is None else ~ex
        new = _camera(depth).points_world(
            stride=stride, mask=mask, min_depth_m=0.05, max_depth_m=6.0
        )
        old = _old_map_depth_points_world(depth, stride, ex)
        assert new.shape == old.shape and len(new) > 100
        # the same pixels in the same order; the old code multiplied in another order
        # (d / fx after (u − cx) · d, and a homogeneous product): equal to rounding
        np.testing.assert_allclose(new, old, rtol=0, atol=1e-12)


def test_navigation_sees_through_the_same_cells_as_before() -> None:
    grid = Grid(np.zeros((80, 80), bool), 0.1, (-2.0, -2.0))
    iy, ix = (a.reshape(-1).astype(np.int64) for a in np.mgrid[0:80, 0:80])
    for seed in range(3):
        depth = _depth(seed)
        new = seen_through(_camera(depth), grid, iy, ix, DepthParams())
        old = _old_seen_through(depth, grid, iy, ix)
        np.testing.assert_array_equal(new, old)
        assert old.any() and not old.all()
    assert len(seen_through(_camera(_depth()), grid, iy[:0], ix[:0], DepthParams())) == 0


def test_the_map_looks_at_the_same_places_as_before() -> None:
    rng = np.random.default_rng(7)
    points = np.column_stack(
        [rng.uniform(-3.0, 6.0, 4000), rng.uniform(-2.0, 7.0, 4000), rng.uniform(-0.5, 2.0, 4000)]
    )
    for seed in range(2):
        depth = _depth(seed)
        cam = _camera(depth)
        new = [looks_at(cam, p, 3.5) for p in points]
        old = [_old_looks_at(depth, p, 3.5) for p in points]
        assert new == old
        assert 50 < sum(old) < len(old)


# -- the camera's own contracts ------------------------------------------------------------


def test_a_world_point_projects_to_its_pixel_and_back() -> None:
    cam = _camera()
    p_world = transform_points(T_WORLD_CAMERA, [0.3, -0.2, 2.5])
    uv, z = cam.project_world(p_world)
    assert z[0] == pytest.approx(2.5)
    np.testing.assert_allclose(uv[0], [FX * 0.3 / 2.5 + CX, FY * -0.2 / 2.5 + CY])
    np.testing.assert_allclose(cam.to_world(cam.unproject(uv, z)), p_world, atol=1e-12)


def test_a_frame_sees_past_a_point_in_its_picture_with_the_depth_beyond_it() -> None:
    depth = np.full((H, W), 3.0, np.float32)  # a wall 3 m ahead along the optical axis
    depth[:, 20:30] = 0.0  # no return
    cam = _camera(depth)
    pts_cam = np.array([
        [0.0, 0.0, 2.0],  # 1 m before the wall: seen past
        [0.0, 0.0, 2.95],  # on the wall's face: not (a wall's top seen is no top)
        [0.0, 0.0, 3.5],  # behind the wall: not
        [10.0, 0.0, 2.0],  # off the picture's right: not
        [0.0, -10.0, 2.0],  # above the picture: not
        [0.0, 0.0, -2.0],  # behind the camera: not
        [(25 - CX) * 6.0 / FX, 0.0, 6.0],  # column 25, no return: nothing there
    ])  # fmt: skip
    got = sees_over(cam, transform_points(T_WORLD_CAMERA, pts_cam))
    assert got.tolist() == [True, False, False, False, False, False, True]


def test_points_behind_the_camera_have_no_pixel() -> None:
    uv, z = _camera().project([[0.1, 0.2, -1.0], [0.1, 0.2, 0.0], [0.0, 0.0, 1.0]])
    assert np.isnan(uv[:2]).all() and list(z) == [-1.0, 0.0, 1.0]
    np.testing.assert_allclose(uv[2], [CX, CY])


def test_optical_frame_right_is_plus_u_down_is_plus_v() -> None:
    cam = PinholeCamera(100.0, 100.0, 50.0, 40.0)  # at the world origin, optical = world
    uv, _ = cam.project([[0.5, 0.0, 1.0], [0.0, 0.5, 1.0]])
    assert uv[0, 0] > 50.0 and uv[1, 1] > 40.0


def test_valid_depth_and_strides() -> None:
    d = np.array([[0.0, np.nan, np.inf, -1.0, 0.04, 0.06, 5.9, 6.0, 7.0]])
    assert valid_depth(d).tolist() == [[False, False, False, False, True, True, True, True, True]]
    kept = valid_depth(d, 0.05, 6.0).tolist()
    assert kept == [[False, False, False, False, False, True, True, False, False]]
    depth = np.ones((5, 7))
    pts = backproject(depth, PinholeCamera(1.0, 1.0, 0.0, 0.0), stride=3)
    # pixels (0, 0), (3, 0), (6, 0), (0, 3), (3, 3), (6, 3): row-major, u = x at unit depth
    np.testing.assert_array_equal(pts[:, 0], [0, 3, 6, 0, 3, 6])
    np.testing.assert_array_equal(pts[:, 1], [0, 0, 0, 3, 3, 3])


def test_a_mask_of_another_shape_and_a_camera_without_depth_are_refused() -> None:
    with pytest.raises(ValueError, match="mask shape"):
        backproject(np.ones((4, 4)), _camera(), mask=np.ones((4, 5), bool))
    with pytest.raises(ValueError, match="no depth image"):
        _camera().points_world()
