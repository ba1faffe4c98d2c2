r"""The multi-agent system written as one plant (Section AIHMAS), for the scenario builders.

The composition itself -- :func:`compose_mas` (``A = diag(breve A_i)``,
``B^i = [0 breve B_i^T 0]^T``, ``C_i = [0 breve C_i 0]``, ``known[i] = (i,)``, ``links[i] = i``),
:class:`MASComposition`, :func:`embed_block`, :func:`agent_offsets` -- is pure matrix arithmetic
and lives in the design layer, :mod:`dobs_envs.design.mas_composition`, which the MAS observer
(:func:`~dobs_envs.design.observer.design_mas_observer`) shares; it is re-exported here under the
same names. This module adds what only scenarios need: the named O-O topologies of the
generators and scenario files (:data:`TOPOLOGIES`) and NE1's default graph (:func:`ring_or_path`).
"""
from __future__ import annotations

from ..design.mas_composition import MASComposition, agent_offsets, compose_mas, embed_block
from ..graphs import Graph, complete_graph, path_graph, ring_graph, star_graph

__all__ = ["MASComposition", "compose_mas", "embed_block", "agent_offsets", "TOPOLOGIES", "ring_or_path"]

#: Named O-O topologies with unit weights (Section commugraph): name -> ``f(N) -> Graph``.
TOPOLOGIES = {"ring": ring_graph, "path": path_graph, "star": star_graph, "complete": complete_graph}


def ring_or_path(N: int) -> Graph:
    """The ring ``0-1-...-(N-1)-0`` with unit weights (NE1's and NE2's O-O graph), a path for ``N < 3``.

    A ring needs three nodes; with one or two nodes the path is the only connected graph
    (Assumption 5).
    """
    return ring_graph(N) if N >= 3 else path_graph(N)
