"""`troubles_in`: what a failed run's report keeps of a service's log (CI keeps no logs)."""

from __future__ import annotations

from deploy.stack import troubles_in

LOG = """\
2026-11-27 12:51:32,727 navigation INFO common.service: navigation runs on CPUs [1] (rest)
2026-11-27 12:51:35,638 navigation WARNING dume.navigation: body guard: stand
2026-11-27 12:51:36,062 navigation INFO dume.navigation: map from semantic map
Traceback (most recent call last):
  File "services/navigation/node.py", line 10, in tick
    self._caps(now)
ValueError: math domain error

During handling of the above exception, another exception occurred:

Traceback (most recent call last):
  File "common/service.py", line 3, in run
RuntimeError: tick failed
2026-11-27 12:51:37,000 navigation INFO dume.navigation: goal nav_2 succeeded
2026-11-27 12:51:38,000 navigation ERROR common.service: navigation stopped
"""


def test_a_log_gives_its_warnings_errors_and_whole_tracebacks_and_nothing_else() -> None:
    said = troubles_in(LOG)
    assert said[0].endswith("body guard: stand")
    assert said[1:5] == LOG.splitlines()[3:7]  # the first traceback, its exception's line last
    assert "During handling of the above exception, another exception occurred:" in said
    assert said[-2] == "RuntimeError: tick failed"
    assert said[-1].endswith("navigation stopped")
    assert not any(" INFO " in line for line in said)


def test_a_quiet_log_gives_nothing() -> None:
    assert troubles_in("2026-11-27 12:51:32,727 sim INFO common.service: ready\n") == []
