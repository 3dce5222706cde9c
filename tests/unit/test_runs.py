"""Which runs there are and which are up (`deploy.runs`), on real folders: a run is up
while the process that holds it lives and it has not ended; a run is found by its id or
a prefix of it, the newest by default; a name that fits none or several says so."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from deploy.runs import (
    RunInfo,
    RunNotFound,
    all_runs,
    ctl_secret,
    find_run,
    listening,
    mark_ended,
    now_iso,
    pid_alive,
    read_info,
    restarts,
    runs_up,
    write_info,
)


def _dead_pid() -> int:
    proc = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                          capture_output=True, text=True, check=True)  # fmt: skip
    return int(proc.stdout)


def _run(root: Path, run_id: str, pid: int, kind: str = "up", port: int = 7447) -> Path:
    folder = root / run_id
    write_info(folder, RunInfo(run_id=run_id, port=port, pid=pid, kind=kind,  # type: ignore[arg-type]
                               world="hall", world_seed=0, started=now_iso()))  # fmt: skip
    return folder


def test_runs_are_up_while_their_process_lives_and_until_they_end(tmp_path: Path) -> None:
    _run(tmp_path, "20261125-100000-aaaaaa", os.getpid(), port=7450)
    _run(tmp_path, "20261125-110000-bbbbbb", _dead_pid())
    later = _run(tmp_path, "20261125-120000-cccccc", os.getpid(), kind="stack")
    (tmp_path / "20261125-130000-dddddd").mkdir()  # a folder without run.json: no run
    assert [r.info.run_id[-6:] for r in all_runs(tmp_path)] == ["cccccc", "bbbbbb", "aaaaaa"]
    assert [r.info.run_id[-6:] for r in runs_up(tmp_path)] == ["cccccc", "aaaaaa"]
    mark_ended(later)
    info = read_info(later)
    assert info is not None and info.ended
    assert [r.info.run_id[-6:] for r in runs_up(tmp_path)] == ["aaaaaa"]


def test_a_run_is_found_by_id_prefix_or_as_the_newest_up(tmp_path: Path) -> None:
    with pytest.raises(RunNotFound, match="start one with `dume up`"):
        find_run(None, tmp_path)
    _run(tmp_path, "20261125-100000-aaaaaa", os.getpid())
    _run(tmp_path, "20261125-110000-bbbbbb", _dead_pid())
    _run(tmp_path, "20261125-120000-cccccc", os.getpid(), kind="stack")
    assert find_run(None, tmp_path).info.run_id.endswith("cccccc")  # the newest up
    assert find_run(None, tmp_path, supervised=True).info.run_id.endswith("aaaaaa")
    assert find_run("20261125-11", tmp_path).info.run_id.endswith("bbbbbb")
    with pytest.raises(RunNotFound, match="names 3 runs"):
        find_run("20261125", tmp_path)
    with pytest.raises(RunNotFound, match=r"no run 'x' in .* \(newest: 20261125-120000-cccccc"):
        find_run("x", tmp_path)


def test_a_pid_the_system_gave_to_a_later_process_is_not_the_run(tmp_path: Path) -> None:
    """A run whose holder died unmarked left its pid; a process started after the run
    that got the same pid is not the run (`dume down` once stopped another stack's map
    service so)."""
    _run(tmp_path, "20261125-100000-aaaaaa", os.getpid())
    assert find_run(None, tmp_path).up
    stale = tmp_path / "20261125-090000-eeeeee"
    before = "2020-01-01T00:00:00Z"  # long before this process began
    info = RunInfo(run_id=stale.name, port=7447, pid=os.getpid(), kind="up", world="hall",
                   world_seed=0, started=before)  # fmt: skip
    write_info(stale, info)
    assert [r.info.run_id[-6:] for r in runs_up(tmp_path)] == ["aaaaaa"]
    assert find_run(None, tmp_path, port=7447).info.run_id.endswith("aaaaaa")
    _run(tmp_path, "20261125-110000-ffffff", os.getpid(), port=7460)
    assert find_run(None, tmp_path, port=7447).info.run_id.endswith("aaaaaa")
    assert find_run(None, tmp_path, port=7460).info.run_id.endswith("ffffff")
    with pytest.raises(RunNotFound, match="run on port 7470"):
        find_run(None, tmp_path, port=7470)


def test_the_control_secret_is_the_owners_and_stays_the_same(tmp_path: Path) -> None:
    secret = ctl_secret(tmp_path)
    assert len(secret) == 32 and ctl_secret(tmp_path) == secret
    assert (tmp_path / "ctl.secret").stat().st_mode & 0o777 == 0o600


def test_listening_tells_an_open_port_from_a_closed_one() -> None:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        assert listening("127.0.0.1", port)
    assert not listening("127.0.0.1", port, timeout_s=0.2)


def test_unexpected_exits_are_counted_from_supervisords_log(tmp_path: Path) -> None:
    assert restarts(tmp_path) == {}
    (tmp_path / "supervisord.log").write_text(
        "2026-11-25 18:30:56,814 INFO spawned: 'sim' with pid 19592\n"
        "2026-11-25 18:31:35,072 WARN exited: sim (terminated by SIGKILL; not expected)\n"
        "2026-11-25 18:31:36,072 INFO spawned: 'sim' with pid 19601\n"
        "2026-11-25 18:32:35,072 WARN exited: wbc (exit status 1; not expected)\n"
        "2026-11-25 18:33:35,072 WARN exited: sim (terminated by SIGKILL; not expected)\n"
        "2026-11-25 18:40:00,000 INFO exited: mission (exit status 0; expected)\n"
    )
    assert restarts(tmp_path) == {"sim": 2, "wbc": 1}


def test_a_process_that_exited_is_not_alive_even_before_it_is_reaped() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    deadline = time.monotonic() + 10
    while pid_alive(proc.pid) and time.monotonic() < deadline:  # a zombie until wait()
        time.sleep(0.05)
    assert not pid_alive(proc.pid)
    proc.wait()
    assert pid_alive(os.getpid())
