"""Every ```python block of README.md and docs/**/*.md runs, and the facts the pages state about the code
hold: the README's spaces are the environments' spaces, the equation-label map names files that hold the
labels, the README's test command is the one CI runs.

A block may be preceded by one marker line (an HTML comment, invisible in the rendered page):

- ``<!-- snippet: replace OLD -> NEW (reason) -->``: run with ``OLD`` replaced by ``NEW``; only for blocks
  that would otherwise train for minutes (a training budget), so the block still runs end to end;
- ``<!-- snippet: heavy-clients (reason) -->``: the RLlib and BenchMARL blocks, whose pins conflict with the
  main environment: ``tests/clients_heavy/test_docs_blocks.py`` runs them in the heavy-clients virtual
  environment (``.ci/run``); the main suite skips them.
"""
from __future__ import annotations

import glob
import importlib
import os
import re
import sys

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
_FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
_MARKER = re.compile(r"<!-- snippet: (replace|heavy-clients) ?(.*?) -->\s*$")


def _pages() -> list[str]:
    docs = sorted(glob.glob(os.path.join(ROOT, "docs", "**", "*.md"), recursive=True))
    generated = os.path.join(ROOT, "docs", "environments")
    return [os.path.join(ROOT, "README.md")] + [p for p in docs if not (
        os.path.dirname(p) == generated and p.endswith("_v0.md"))]


def snippets() -> list[tuple[str, str, str | None]]:
    """``(id, code, marker)`` for every ```python block, the marker from the line before the fence."""
    out = []
    for path in _pages():
        text = open(path).read()
        for k, m in enumerate(_FENCE.finditer(text)):
            before = text[:m.start()].rstrip("\n").rsplit("\n", 1)[-1]
            marker = _MARKER.search(before)
            out.append((f"{os.path.relpath(path, ROOT)}#{k}", m.group(1), marker and marker.group(0)))
    return out


SNIPPETS = snippets()


def test_snippets_are_found_and_markers_are_few():
    """The collection sees the pages' blocks; the markers stay the exception they are meant to be."""
    ids = [s[0] for s in SNIPPETS]
    assert any(i.startswith("README.md#") for i in ids) and any(i.startswith("docs/") for i in ids)
    marked = [s for s in SNIPPETS if s[2]]
    assert len(marked) <= 5, [s[0] for s in marked]
    for _, code, marker in marked:
        kind, rest = _MARKER.search(marker).groups()
        if kind == "replace":
            old = rest.split(" -> ")[0]
            assert old in code, (old, marker)  # a stale marker would silently run the long version


def run_snippet(sid: str, code: str, tmp_path, monkeypatch) -> None:
    """Run one block as a script would: a fresh namespace, in ``tmp_path``, ``examples/`` importable."""
    # one torch thread, as in the benchmark's workers: on a loaded 2-core machine torch's default two
    # threads made the 2k-step PPO block take 62 s instead of 4 s (measured side by side)
    try:
        import torch
    except ImportError:
        torch = None
    if torch is not None:
        threads = torch.get_num_threads()
        torch.set_num_threads(1)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    monkeypatch.chdir(tmp_path)  # a block that writes files writes them here
    monkeypatch.syspath_prepend(os.path.join(ROOT, "examples"))
    try:
        exec(compile(code, sid, "exec"), {"__name__": "__snippet__"})
    finally:
        if torch is not None:
            torch.set_num_threads(threads)


@pytest.mark.parametrize("sid,code,marker", SNIPPETS, ids=[s[0] for s in SNIPPETS])
def test_snippet_runs(sid, code, marker, tmp_path, monkeypatch):
    if marker:
        kind, rest = _MARKER.search(marker).groups()
        if kind == "heavy-clients":
            pytest.skip("run in the heavy-clients virtual environment (tests/clients_heavy/test_docs_blocks.py)")
        else:
            old, new = re.match(r"(\S+) -> (\S+)", rest).groups()
            code = code.replace(old, new)
    run_snippet(sid, code, tmp_path, monkeypatch)


def test_readme_environment_spaces_are_the_environments():
    """The README's environments table gives each environment's agents, per-agent observation widths and
    centralised spaces as the environments report them with default arguments."""
    import gymnasium as gym

    import dobs_envs  # noqa: F401
    from dobs_envs.registry import ENVIRONMENTS

    text = open(os.path.join(ROOT, "README.md")).read()
    for entry in ENVIRONMENTS.values():
        row = next(line for line in text.splitlines() if line.startswith(f"| `{entry.module}` |"))
        cells = [c.strip() for c in row.strip("|").split("|")]
        pe = importlib.import_module(entry.module).parallel_env()
        genv = gym.make(entry.gym_id)
        assert cells[1] == f"`{entry.gym_id}`"
        assert cells[3] == str(len(pe.possible_agents)), entry.name
        widths = [pe.observation_space(a).shape for a in pe.possible_agents]
        assert cells[4] == (str(widths[0]) if len(set(widths)) == 1 else ", ".join(map(str, widths))), (entry.name, cells[4])
        assert cells[5] == f"{genv.observation_space.shape} / {genv.action_space.shape}", entry.name


def test_equation_label_map_names_files_that_hold_the_labels():
    """docs/concepts.md maps the paper's equation labels to files: each named file contains its label."""
    text = open(os.path.join(ROOT, "docs", "concepts.md")).read()
    section = text.split("## The paper's equation labels in the code", 1)[1]
    rows = [line for line in section.splitlines() if line.startswith("| ") and not line.startswith("| label")]
    assert len(rows) >= 15
    for row in rows:
        label, _, files = [c.strip() for c in row.strip("|").split("|")]
        paths = re.findall(r"`([^`]+\.py)`", files)
        assert paths, row
        for p in paths:
            assert re.search(rf"\b{re.escape(label)}\b", open(os.path.join(ROOT, p)).read()), (label, p)


def test_readme_test_command_is_the_one_ci_runs():
    """.ci/run runs exactly the test command the README gives."""
    readme = open(os.path.join(ROOT, "README.md")).read()
    ci = open(os.path.join(ROOT, ".ci", "run")).read()
    command = re.search(r"&& (python -m pytest[^\n`]*)\n", readme).group(1)
    assert re.search(rf"^{re.escape(command)}$", ci, re.M), command


def test_no_development_jargon_in_user_facing_text():
    """Pages and the environment docstrings they render speak to users, not to the project's history."""
    from dobs_envs.registry import ENVIRONMENTS

    texts = {p: open(p).read() for p in _pages()}
    for entry in ENVIRONMENTS.values():
        mod, cls = entry.entry_point.split(":")
        texts[entry.entry_point] = getattr(importlib.import_module(mod), cls).__doc__
    bad = re.compile(r"\bissue \d+|today's recipe|\bsessions?\b|\bhoped\b|git history", re.I)
    for where, text in texts.items():
        assert not bad.search(text), (where, bad.search(text).group(0))



def test_headline_numbers_are_in_the_published_tables():
    """The README's and the findings page's headline tables copy their numbers from the results tables
    (which tests/test_results_archive.py checks against the stored records): every "IQM [low, high]" and
    every analytic ratio of a headline row is in the matching row of a table in docs/results."""
    pages = sorted(p for p in os.listdir(os.path.join(ROOT, "docs", "results")) if p.endswith(".md") and p != "index.md")
    rows = [line for p in pages for line in open(os.path.join(ROOT, "docs", "results", p)).read().splitlines()
            if line.startswith("| ")]
    for page in ("README.md", os.path.join("docs", "results", "index.md")):
        text = open(os.path.join(ROOT, page)).read()
        section = text.split("| environment (budget, runs per agent) |", 1)[1]
        headline = []
        for line in section.splitlines()[2:]:
            if not line.startswith("| "):
                break
            headline.append(line)
        assert len(headline) == 5, page
        for line in headline:
            cells = [c.strip() for c in line.strip("|").split("|")]
            for interval in re.findall(r"\d[\d.e+]* \[[^\]]+\]", " ".join(cells[1:3])):
                assert any(f"| {interval} |" in r for r in rows), (page, interval)
            for ratio in cells[3:5]:  # Kalman + paper law, LQG: the analytic rows
                assert any(f"| {ratio} | {ratio} |" in r for r in rows), (page, ratio)
