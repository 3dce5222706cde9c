"""`dume`'s errors are one line with a cause and a hint, never a traceback: what the
command line does with each kind of failure a command can end in (`deploy.cli.main`)."""

from __future__ import annotations

from pathlib import Path

import pytest

import deploy.cli as cli
from common.bus import NoReply, NoRouter, RemoteError
from common.messages.errors import ErrorReply


def _fails_with(monkeypatch: pytest.MonkeyPatch, exc: BaseException) -> None:
    def command(_args: object) -> int:
        raise exc

    monkeypatch.setattr(cli, "cmd_status", command)


@pytest.mark.parametrize(
    ("exc", "code", "said"),
    [
        (NoReply("dume/map/artifacts: no reply within 5.0 s"), 1,
         "dume: no answer from the stack: dume/map/artifacts: no reply within 5.0 s "
         "(is the stack still starting? `dume status` says who is ready)"),
        (NoRouter("no dume stack answers on tcp/127.0.0.1:7447: Unable to connect. Timeout! "
                  "at /root/.cargo/git/checkouts/zenoh/src/net/runtime/orchestrator.rs:388."), 1,
         "dume: no dume stack answers on tcp/127.0.0.1:7447: Unable to connect. Timeout! "
         "(start one with `dume up`, or pass the --port that `dume demo` printed)"),
        (RemoteError("dume/map/import", ErrorReply(code="invalid", message="an id twice",
                                                   key="dume/map/import")), 1,
         "dume: dume/map/import: invalid: an id twice (`dume logs` shows the run's logs)"),
        (FileNotFoundError(2, "No such file or directory", "/x/map.json"), 1,
         "dume: cannot use /x/map.json: No such file or directory"),
        (cli.CliError("the mission service is not running", "`dume status`"), 1,
         "dume: the mission service is not running (`dume status`)"),
    ],
)  # fmt: skip
def test_each_kind_of_failure_is_one_line_with_its_cause_and_a_hint(
    monkeypatch: pytest.MonkeyPatch,
    capsys: pytest.CaptureFixture[str],
    exc: BaseException,
    code: int,
    said: str,
) -> None:
    _fails_with(monkeypatch, exc)
    assert cli.main(["status"]) == code
    err = capsys.readouterr().err
    (line,) = err.strip().splitlines()
    assert line.startswith(said), line
    assert ".rs" not in line and "Traceback" not in err


def test_a_bug_is_one_line_and_its_traceback_goes_to_a_file(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    log = tmp_path / "cli-errors.log"
    monkeypatch.setattr(cli, "CLI_ERRORS", log)
    _fails_with(monkeypatch, KeyError("oops"))
    assert cli.main(["status"]) == 70
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("dume: internal error: KeyError: 'oops' (the traceback is in ")
    assert "Traceback (most recent call last)" in log.read_text()
    assert "KeyError: 'oops'" in log.read_text()
