"""The one shape of an analysis request: its catalogue key, the chain it chooses, its options document."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

import analysis.request
from analysis import PAPER_CHAIN, AnalysisRequest, Recording, TwoMassParams, code_fingerprint, our_chain


def _recording(phases: tuple[str, ...]) -> Recording:
    return Recording(current_a={p: np.zeros(8) for p in phases}, rate_hz=25600.0, encoder_index=np.arange(8),
                     position_counts=np.zeros(8, np.int64), period_s=1e-3, counts_per_rev=4096, pole_pairs=4,
                     k_t_Nm_per_A=0.1)


ONE, THREE = _recording(("i_a",)), _recording(("i_a", "i_b", "i_c"))


def test_key_is_the_request_as_asked_and_the_code(monkeypatch: pytest.MonkeyPatch) -> None:
    asked = AnalysisRequest()
    key = json.loads(asked.key())
    assert key == {"torque_method": None, "params": "K,Jm,Jl", "fit": "amplitude", "band_hz": None, "align": True,
                   "segment_s": 0.5, "nominal": None, "inertia_tolerance": None, "pipeline": "acq", "partial": False,
                   "select_segments": None, "analysis": code_fingerprint()}
    others = [replace(asked, params="K"), replace(asked, band_hz=(20.0, 300.0)), replace(asked, pipeline="paper"),
              replace(asked, partial=True), replace(asked, torque_method="encoder"),
              replace(asked, select_segments=True), replace(asked, select_segments=False),
              replace(asked, nominal=TwoMassParams(900.0, 1e-4, 5e-4, 0.0)), replace(asked, inertia_tolerance=0.15)]
    assert len({asked.key(), *(o.key() for o in others)}) == 1 + len(others)
    monkeypatch.setattr(analysis.request, "code_fingerprint", lambda: "other code")
    assert asked.key() != json.dumps(key, sort_keys=True)


def test_segments_are_selected_by_default_where_acq_did_not_command_the_motion() -> None:
    """A monitor's window or an import has no profile: the default request averages only its exciting segments, as
    acq monitor does; a recording of acq's own profile, the paper's chain or an explicit choice do not change."""
    from analysis import CommandedProfile

    commanded = replace(ONE, profile=CommandedProfile(0.05, 0.05, 0.0, 0.02))
    assert AnalysisRequest().selects_segments(ONE) and not AnalysisRequest().selects_segments(commanded)
    assert not AnalysisRequest(pipeline="paper").selects_segments(ONE)
    assert not AnalysisRequest(select_segments=False).selects_segments(ONE)
    assert AnalysisRequest(select_segments=True).selects_segments(commanded)


def test_chain_resolves_the_torque_method_by_the_phases() -> None:
    assert AnalysisRequest().chain(ONE) == our_chain("encoder")
    assert AnalysisRequest().chain(THREE) == our_chain("park")
    assert AnalysisRequest(torque_method="hilbert", align=False).chain(THREE) == our_chain("hilbert", align=False)
    assert AnalysisRequest(pipeline="paper", torque_method="park").chain(THREE) is PAPER_CHAIN
    assert (PAPER_CHAIN.torque_method, PAPER_CHAIN.align, PAPER_CHAIN.resampling, PAPER_CHAIN.weighting) == (
        "hilbert", False, "linear", "uniform")


def test_options_document_says_what_ran_and_gives_the_request_back() -> None:
    asked = AnalysisRequest(params="K", fit="complex", band_hz=(20.0, 300.0))
    doc = json.loads(json.dumps(asked.to_json_dict(asked.chain(THREE))))
    assert doc == {"pipeline": "acq", "torque_method": "park", "params": "K", "fit": "complex", "band_hz": [20.0, 300.0],
                   "align": True, "segment_s": 0.5, "nominal": None, "inertia_tolerance": None}
    assert AnalysisRequest.from_json_dict(doc) == replace(asked, torque_method="park")
    # the bench's tolerance is the application's to fill in, as its nominal values are
    assert AnalysisRequest.from_json_dict({**doc, "inertia_tolerance": 0.15}).inertia_tolerance is None
    paper = AnalysisRequest(pipeline="paper")
    assert paper.to_json_dict()["torque_method"] is None  # as asked; what ran says hilbert
    again = AnalysisRequest.from_json_dict(paper.to_json_dict(PAPER_CHAIN))
    assert again.torque_method is None and again.chain(THREE) is PAPER_CHAIN
    with pytest.raises(TypeError):
        AnalysisRequest.from_json_dict({"band_hz": 5})


def test_a_request_naming_none_of_the_defaults_options_is_filed_as_asked_on_every_recording() -> None:
    """The batch reads a session for the request it is filed under only when the request names one of the options
    :meth:`AnalysisRequest.as_default_where_it_is` looks at: every other request is that request on any recording."""
    plain = [AnalysisRequest(), AnalysisRequest(params="K", nominal=TwoMassParams(900.0, 1e-4, 5e-4, 0.0)),
             AnalysisRequest(fit="complex"), AnalysisRequest(pipeline="paper"), AnalysisRequest(partial=True),
             AnalysisRequest(segment_s=1.0), AnalysisRequest(align=False)]
    for request in plain:
        assert not request.names_options_of_the_default()
        assert all(request.as_default_where_it_is(rec) == request for rec in (ONE, THREE))
    naming = [AnalysisRequest(band_hz=(10.0, 400.0)), AnalysisRequest(torque_method="encoder"),
              AnalysisRequest(select_segments=True)]
    assert all(request.names_options_of_the_default() for request in naming)
    # each names what the default does on a one-phase recording without a profile: filed as the default request
    assert [r.as_default_where_it_is(ONE) for r in naming] == [AnalysisRequest()] * 3
