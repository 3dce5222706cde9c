"""Every key every service takes, fuzzed over a live stack (`dume trial fuzz`, fewer
cases): no service crashes, none logs an exception, every one stays alive, and the
mission still takes a request afterwards."""

from __future__ import annotations

import pytest

from bench.trial_fuzz import run_fuzz

pytestmark = [pytest.mark.integration, pytest.mark.slow]


def test_fuzzing_every_key_crashes_no_service() -> None:
    r = run_fuzz(count=100, seed=1)
    assert r["keys"] >= 30, "the services said what they take"
    assert r["crashed"] == [] and r["keys_with_a_service_down"] == [], r
    assert r["logged_exceptions"] == {}, r["logged_exceptions"]
    assert r["fetch_after"] == "held: after-fuzz"
    serves = [k for k in r["per_key"] if k["kind"] == "serve"]
    assert all(k["answers"] + k["errors"] > 0 for k in serves), "every queryable answered"
