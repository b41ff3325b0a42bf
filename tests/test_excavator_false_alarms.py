"""The load cut's decision margin includes the cut's own model error (issue 32, item 3):
what the joint's load model leaves on the fit recordings it is fitted on (by the load
identified there or by any friction candidate fitted there), less their noise, is added to
the noise's threshold; a holdout gap within it is no finding (before: ``unexplained@arm``
on effect-free cases of the blind benchmark, the arm's gap 0.39 % against 0.29 %)."""
import math

import pytest

from boomfmi.diagnose.joints import CutFinding, Fitted, _decide, _model_error, threshold


def _cut(gap, noise, fit_gap, candidates):
    return CutFinding("position", [gap], [noise], fit_gap=fit_gap, candidates=candidates)


def test_a_gap_within_the_models_own_error_is_no_finding():
    # the blind benchmark's case 8 (effect-free arm): holdout gap 0.39 %, noise 0.03 %,
    # the fit recordings left at 0.15 % by the best fit there
    cut = _cut(0.0039, 0.0003, 0.0016, [Fitted("stribeck_friction", {}, 0.0015, [0.0038], 0.026),
                                        Fitted("pressure_friction", {}, math.nan, [], 0.0, not_fitted="too few")])
    assert cut.flagged                                  # the noise's threshold alone: 0.29 %
    cut.model_error = _model_error(cut, 0.0003)
    assert cut.model_error == pytest.approx(0.0012)     # the least fit gap less the noise
    assert cut.thresholds == [pytest.approx(threshold(0.0003) + 0.0012)]
    assert not cut.flagged
    _decide(cut, [])
    assert cut.verdict == []                            # not "unexplained"


def test_a_friction_effect_the_fit_recordings_show_is_still_named():
    # the candidate takes the fit recordings' gap down to their noise: no model error to
    # hide behind, the holdout's gap is beyond the threshold and the candidate explains it
    best = Fitted("pressure_friction", {}, 0.0004, [0.0010], 1.0 - 0.0010 / 0.0060)
    cut = _cut(0.0060, 0.0003, 0.0045, [best, Fitted("stribeck_friction", {}, 0.0030, [0.0050], 0.17)])
    cut.model_error = _model_error(cut, 0.0003)
    assert cut.model_error == pytest.approx(0.0001)
    assert cut.flagged
    _decide(cut, [])
    assert cut.verdict == ["pressure_friction"]


def test_a_gap_beyond_the_models_error_that_nothing_explains_stays_unexplained():
    cut = _cut(0.0100, 0.0003, 0.0016, [Fitted("stribeck_friction", {}, 0.0015, [0.0098], 0.02)])
    cut.model_error = _model_error(cut, 0.0003)
    assert cut.flagged
    _decide(cut, [])
    assert cut.verdict == ["unexplained"]
