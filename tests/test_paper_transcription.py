"""The tests' transcription of NE2/NE3 (tests/paper_ne2.py) agrees with the package's
(dobs_envs.scenarios.paper), and the scenarios' own designs reproduce the printed T_id table.
Every other test takes NE2 from tests/paper_ne2.py, so a typo in either transcription fails here."""
from __future__ import annotations

import numpy as np
import pytest

import paper_ne2 as NE2
from dobs_envs.design.subspaces import projector_distance
from dobs_envs.scenarios.paper import ne2, ne2_ablation, ne2_plant, ne3


def test_plant_matches_the_package():
    A, channels, C = ne2_plant()
    np.testing.assert_array_equal(A, NE2.A())
    assert len(channels) == NE2.N_CHANNELS and len(C) == NE2.N_NODES
    for got, want in zip(channels, NE2.channels()):
        np.testing.assert_array_equal(got, want)
    for got, want in zip(C, NE2.outputs()):
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("make", [ne2, ne2_ablation, ne3])
def test_scenarios_use_the_transcribed_plant_and_knowledge(make):
    sc = make()
    np.testing.assert_array_equal(sc.A, NE2.A())
    np.testing.assert_array_equal(np.hstack(sc.channels), np.hstack(NE2.channels()))
    assert [tuple(k) for k in sc.known] == [(k,) for k in NE2.KNOWN]
    if make is ne3:
        np.testing.assert_array_equal(sc.B_v, NE2.b_v())


@pytest.mark.parametrize("make,ne3_table", [(ne2, False), (ne3, True)])
def test_scenario_designs_reproduce_the_printed_T_d(make, ne3_table):
    d = make().design
    for i in range(NE2.N_NODES):
        T = NE2.t_d(i, ne3=ne3_table)
        assert d.delta[i] == T.shape[1]
        assert projector_distance(d.T_d[i], T) < 1e-8, f"node {i}"


def test_the_table_is_orthonormal():
    """The printed T_id have orthonormal columns (Lemma 2's T_i = [T_id T_iu] is orthogonal)."""
    for i in range(NE2.N_NODES):
        for ne3_table in (False, True):
            T = NE2.t_d(i, ne3=ne3_table)
            np.testing.assert_allclose(T.T @ T, np.eye(T.shape[1]), atol=1e-15)
