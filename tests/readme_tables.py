"""Compare a published results table (a Markdown page of the docs, ``docs/results/*.md``) with the ``results.json`` its command writes: number by number, each
with a tolerance suited to its quantity (not text: a chattering steady-state error differs in its last
digits between machines, 0.000806 against 0.000804 was seen)."""
from __future__ import annotations

import json
import os
import re

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_NUM = re.compile(r"[-+]?\d+(?:\.\d+)?(?:e[-+]?\d+)?")

#: table column header -> (results.json keys of the numbers in the cell, relative tolerance beyond the
#: printed rounding). Cost ratios and costs are sums of the same floating-point terms (1e-3 covers other
#: BLAS/CPU rounding); the steady-state error is an RMS of a chattering O(dt gamma) band (25 %: a paper row
#: printed 5.45e-5 gave 6.08e-5, 12 % more, on an AVX-512 machine); the
#: training time is not a reproducible quantity and is not compared.
COLUMNS = {
    "runs": (("runs",), 0.0),
    "env steps per run": None,
    "train time per run (median)": None,
    "J / J_paper: IQM over runs [95% CI]": (("cost_ratio_iqm", "cost_ratio_ci_low", "cost_ratio_ci_high"), 1e-3),
    "mean J / J_paper [95% CI]": (("cost_ratio_mean", "cost_ratio_mean_ci_low", "cost_ratio_mean_ci_high"), 1e-3),
    "P(J < J_paper) [95% CI]": (("poi", "poi_ci_low", "poi_ci_high"), 1e-9),
    "J / J_paper,fault-free: IQM over runs [95% CI]": (("degradation_iqm", "degradation_ci_low", "degradation_ci_high"), 1e-3),
    "mean J / J_paper,fault-free [95% CI]": (("degradation_mean", "degradation_mean_ci_low", "degradation_mean_ci_high"),
                                             1e-3),
    "transient cost (first 2 s)": (("transient_cost_iqm",), 1e-3),
    "steady-state error (RMS, last 5 s)": (("steady_state_error_iqm",), 0.25),
    "failures": (("failure_rate",), 0.0),
}


def readme_rows(page: str, heading: str) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the Markdown table under ``heading`` in ``page`` (relative to the repository)."""
    lines = open(os.path.join(ROOT, page)).read().splitlines()
    start = lines.index(heading) + 1
    end = next((i for i in range(start, len(lines)) if lines[i].startswith("#")), len(lines))
    table = [line for line in lines[start:end] if line.startswith("|")]
    cells = [[c.strip() for c in line.strip().strip("|").split("|")] for line in table]
    return cells[0], [c for c in cells[2:]]


def _printed_tolerance(text: str) -> float:
    """Half a unit in the last printed digit of ``text`` (a number as the table prints it)."""
    mant, _, exp = text.lower().partition("e")
    decimals = len(mant.partition(".")[2])
    return 0.5 * 10.0 ** (-decimals + (int(exp) if exp else 0))


def check_readme_table(page: str, heading: str, results_json: str) -> None:
    """Every row of the table under ``heading`` in ``page`` is what ``results_json`` gives."""
    header, rows = readme_rows(page, heading)
    doc = json.load(open(results_json))
    got = {r["policy"]: r for r in doc["results"]}
    assert {r[0] for r in rows} == set(got), (heading, sorted(got))
    for row in rows:
        r = got[row[0]]
        for col, cell in zip(header[1:], row[1:]):
            spec = COLUMNS.get(col, "text")
            if spec is None:
                continue
            if spec == "text":
                assert cell == str(r.get({"kind": "kind", "information": "information"}.get(col, col), cell)), (row[0], col)
                continue
            keys, rtol = spec
            nums = _NUM.findall(cell)
            if col == "failures":
                assert abs(float(nums[0]) / 100 - r["failure_rate"]) <= 0.005 + 1e-12, (row[0], cell)
                continue
            assert len(nums) in (1, len(keys)), (row[0], col, cell)
            for key, text in zip(keys, nums):
                want = float(r[key])
                assert abs(float(text) - want) <= _printed_tolerance(text) + rtol * abs(want), (row[0], col, text, want)
