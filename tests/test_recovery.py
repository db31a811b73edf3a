"""Augmented MCL recovers from a kidnapping (scripts/kidnap.py on a small subset)."""

from __future__ import annotations

import importlib.util

import pytest

from mcl.config import PROJECT_ROOT


def _kidnap_module():
    spec = importlib.util.spec_from_file_location("kidnap_script", PROJECT_ROOT / "scripts" / "kidnap.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.slow
def test_recovery_after_a_kidnap_on_three_worlds(tmp_path):
    # Seeds 0-2, kidnapped at 20 s of a 50 s log, the default config with at most 5,000 particles.
    # With recovery: back within 0.5 m (and staying) in < 30 s in all three worlds (measured 1.6-3 s
    # with the full 20,000 in scripts/kidnap.py); without: not recovered in < 30 s in at least one of them
    # (measured: in none of two out of three). Tracking before the jump is the same to 5 mm either way.
    k = _kidnap_module()
    rows = k.experiment([0, 1, 2], kidnap_at=20.0, duration=50.0, overrides=["filter.particles=5000"],
                        root=tmp_path, echo=lambda *_: None)
    assert all(r["recovered"] for r in rows), rows
    assert sum(r["recovery_off"] is not None and r["recovery_off"] < 30.0 for r in rows) < 3, rows
    for r in rows:
        assert r["ate_before_on"] <= r["ate_before_off"] + 0.005, r
        assert r["ate_before_on"] < 0.15, r


def test_recovery_time_rule():
    import numpy as np

    k = _kidnap_module()
    t = np.arange(10.0)
    err = np.array([0.1, 0.1, 5, 5, 0.4, 0.6, 0.3, 0.2, 0.1, 0.1])
    assert k.recovery_time(t, err, 2.0, 0.5) == pytest.approx(4.0)  # below from t = 6 on
    assert k.recovery_time(t, np.r_[err[:-1], 1.0], 2.0, 0.5) is None  # off again at the end
    assert k.recovery_time(t, np.full(10, 0.1), 2.0, 0.5) == 0.0
