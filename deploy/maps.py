"""Saved maps: where `dume up`, `dume demo --map saved` and `dume eval --map saved` find a
world's map.

A saved map is a map file (`dume map --export`, `MapFile`) named after its site
(`hall-seed-0.json` for `hall seed 0`): the robot's own map of that world, explored from
nothing (`dume map --explore`). `var/saved-maps/` holds the ones this machine made (`dume
eval` saves each world it explores there); `deploy/maps/` the ones shipped with dume
(the demo's world). The user's come first. The file records its site, and the map
service refuses a file of another site, so a map is never reused for another world.
"""

from __future__ import annotations

from pathlib import Path

from common.config import REPO_ROOT
from services.semantic_map.store import site_slug

#: This machine's saved maps (`dume eval` writes the worlds it explores here).
SAVED_MAPS = REPO_ROOT / "var" / "saved-maps"
#: The maps shipped with dume.
SHIPPED_MAPS = REPO_ROOT / "deploy" / "maps"


def map_path(folder: Path, site: str) -> Path:
    """The file of `site`'s map in `folder`."""
    return folder / f"{site_slug(site)}.json"


def saved_map(site: str, folders: tuple[Path, ...] | None = None) -> Path | None:
    """The first of `folders` (default: the saved, then the shipped maps) with a map of
    `site` (None: it has not been explored)."""
    for folder in folders or (SAVED_MAPS, SHIPPED_MAPS):
        path = map_path(folder, site)
        if path.is_file():
            return path
    return None


class NoSavedMap(LookupError):
    """A world with no saved map where one is needed: which, and how to make one."""

    def __init__(self, site: str) -> None:
        super().__init__(f"no saved map of {site!r} (in var/saved-maps/ or deploy/maps/)")
        self.hint = (
            "explore it first (`dume eval --worlds 1 --seed N` explores a world it has no "
            "map of and saves the map in var/saved-maps/; or `dume up`, `dume map --explore`, "
            "`dume map --export var/saved-maps/<site>.json`), give a map file (--map FILE), or "
            "--map truth: the map seeded from the world's truth (an ablation)"
        )


def start_from(map_arg: str, site: str) -> dict[str, object]:
    """The map settings of a stack started with `--map map_arg` (the demo's, a fresh
    database of its own): `truth`, the world's truth with noise and the floor plan (the
    ablation); `saved`, the site's saved map (`NoSavedMap` when there is none); else the
    map file `map_arg`. A saved map or a file needs no floor plan: its own grid is the
    static layer (localized on) and its own supports are served."""
    if map_arg == "truth":
        return {"semantic_map.start": "seed-from-world", "semantic_map.floor_plan": "world"}
    path = saved_map(site) if map_arg == "saved" else Path(map_arg).expanduser().resolve()
    if path is None:
        raise NoSavedMap(site)
    if not path.is_file():
        raise FileNotFoundError(f"no map file {map_arg}")
    return {
        "semantic_map.start": "prior",
        "semantic_map.prior_file": str(path),
        "semantic_map.floor_plan": "none",
    }
