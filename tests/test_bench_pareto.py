"""The Pareto criterion of bench/speed_accuracy.py: which variants count as dominated."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "bench"


@pytest.fixture(scope="module")
def sa():
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location("speed_accuracy", BENCH / "speed_accuracy.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCH))
    return module


def test_error_floor_is_16_bit_rounding_noise(sa):
    # Rounding to 16 bits: uniform error in [-q/2, q/2], q = 1/65535, RMSE q/sqrt(12).
    assert sa.ERROR_FLOOR == pytest.approx(1 / 65535 / math.sqrt(12))
    assert -20 * math.log10(sa.ERROR_FLOOR) == pytest.approx(107.1, abs=0.05)
    assert sa.error_cost(1e-3) == 1e-3
    assert sa.error_cost(1e-7) == sa.ERROR_FLOOR


def test_pareto_ties_and_domination(sa):
    # frame time within 5 %: a tie; an error 2x smaller dominates, a 3 % smaller one ties
    assert sa.pareto([(1.0, 2.0), (1.04, 1.0)]) == [False, True]
    assert sa.pareto([(1.0, 2.0), (1.04, 1.94)]) == [True, True]
    # faster and no worse dominates; a faster but worse point stays on the front
    assert sa.pareto([(1.0, 1.0), (0.5, 1.0), (0.4, 3.0)]) == [False, True, True]


def test_errors_below_the_floor_tie_but_not_above(sa):
    # The camera-inside case of session 6: 256 bins at 3.1e-6, 512 bins at 1.1e-6, same frame time.
    default, finer = (89.4e-3, 3.1e-6), (91.3e-3, 1.05e-6)
    assert sa.pareto([default, finer]) == [False, True]  # strictly, the finer table dominates
    cost = [(t, sa.error_cost(e)) for t, e in (default, finer)]
    assert sa.pareto(cost) == [True, True]  # no written image tells them apart
    # above the floor the smaller error still dominates
    cost = [(t, sa.error_cost(e)) for t, e in ((89.4e-3, 3.1e-5), (91.3e-3, 1.05e-5))]
    assert sa.pareto(cost) == [False, True]
    # and a faster variant whose error is also below the floor dominates
    cost = [(t, sa.error_cost(e)) for t, e in ((89.4e-3, 3.1e-6), (60e-3, 4e-6))]
    assert sa.pareto(cost) == [False, True]
