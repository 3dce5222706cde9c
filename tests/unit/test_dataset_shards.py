"""The segmenter's training shards: rendered frames round-trip through `.npz` and load as
class maps for training."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from services.sim import dataset


@pytest.fixture(scope="module")
def small_world_frames() -> tuple[dict[int, str], list[dataset.Frame]]:
    return dataset.render_seed(3, "small")


def test_a_seed_renders_the_same_frames_twice(
    small_world_frames: tuple[dict[int, str], list[dataset.Frame]],
) -> None:
    _, frames = small_world_frames
    _, again = dataset.render_seed(3, "small")
    assert len(frames) == len(again) > 0
    for a, b in zip(frames, again, strict=True):
        assert a.camera == b.camera
        np.testing.assert_array_equal(a.labels, b.labels)
        np.testing.assert_array_equal(a.depth_mm, b.depth_mm)


def test_wrist_frames_show_the_bottle_close_up(
    small_world_frames: tuple[dict[int, str], list[dataset.Frame]],
) -> None:
    names, frames = small_world_frames
    bottle = next(k for k, v in names.items() if v == "bottle_1")
    wrist = [f for f in frames if f.camera == "camera_wrist"][: dataset.WRIST_ARTIFACT_FRAMES]
    pixels = [int(np.count_nonzero(f.labels == bottle)) for f in wrist]
    assert min(pixels) > 100, pixels


def test_a_shard_round_trips(
    tmp_path: Path, small_world_frames: tuple[dict[int, str], list[dataset.Frame]]
) -> None:
    names, frames = small_world_frames
    path = dataset.shard_path(tmp_path, 3)
    dataset.save_shard(path, 3, "small", names, frames)
    assert not list(tmp_path.glob("*.tmp.npz"))
    with np.load(path) as shard:
        assert shard["rgb"].shape == (len(frames), dataset.HEIGHT, dataset.WIDTH, 3)
        assert shard["rgb"].dtype == np.uint8
        np.testing.assert_array_equal(shard["labels"], np.stack([f.labels for f in frames]))
        np.testing.assert_array_equal(shard["depth_mm"], np.stack([f.depth_mm for f in frames]))
        table = dict(zip(shard["label_ids"].tolist(), shard["label_names"].tolist(), strict=True))
        assert table == names
        assert [str(c) for c in shard["camera"]] == [f.camera for f in frames]
        np.testing.assert_allclose(shard["T_base_camera"][0], frames[0].T_base_camera)
        assert int(shard["seed"]) == 3


def test_shards_load_as_class_maps_for_training(
    tmp_path: Path, small_world_frames: tuple[dict[int, str], list[dataset.Frame]]
) -> None:
    from services.perception.training import data

    names, frames = small_world_frames
    path = dataset.shard_path(tmp_path, 3)
    dataset.save_shard(path, 3, "small", names, frames)
    loaded = data.load_frames([path])
    bottle = next(k for k, v in names.items() if v == "bottle_1")
    table = next(k for k, v in names.items() if v.startswith("table"))
    labels = np.stack([f.labels for f in frames])
    assert np.all(loaded.classes[labels == bottle] == data.CLASSES.index("bottle"))
    assert np.all(loaded.classes[labels == table] == 0)  # furniture is background
    assert np.all(loaded.classes[labels == 0] == 0)
