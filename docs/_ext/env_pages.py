"""Sphinx extension: one page per environment, generated from its class docstring.

At ``builder-inited`` it writes ``environments/<module>.md`` (``tracking_v0.md``, ...) for every
entry of :data:`dobs_envs.registry.ENVIRONMENTS`, in Gymnasium's page format:

- a summary table whose spaces are read from the real environments (PettingZoo per agent, and the
  centralised ``gym.make`` view), not copied from text;
- the class docstring's ``## Section`` blocks (Description, Action Space, Observation Space,
  Rewards, Starting State, Episode End, Info, Arguments, Version History), rendered as reST;
- the arguments as a table, from the environment's options dataclass (names, defaults and the
  ``Attributes`` descriptions of :class:`dobs_envs.envs.options.EnvOptions`).

It also writes ``_generated_budgets.md`` (the benchmark's budgets, included by ``benchmark.md``).
The generated files are build products (git-ignored).
"""
from __future__ import annotations

import importlib
import inspect
import os
import re

SECTION = re.compile(r"^## (.+)$", re.M)
#: development references that have no meaning for a reader of the rendered page
_DEV_NOTE = re.compile(r"\s*\(issue \d+\)")


def _fmt_bound(a) -> str:
    import numpy as np

    a = np.asarray(a, dtype=np.float64).ravel()
    if a.size and np.all(a == a[0]):
        v = a[0]
        return "inf" if np.isposinf(v) else "-inf" if np.isneginf(v) else f"{v:.4g}"
    if a.size <= 8:
        return "[" + ", ".join(f"{v:.4g}" for v in a) + "]"
    return "per entry"


def fmt_space(space) -> str:
    """``Box(low, high, shape, dtype)`` with uniform bounds printed once."""
    from gymnasium.spaces import Box

    import numpy as np

    if isinstance(space, Box):
        low, high = np.asarray(space.low, np.float64), np.asarray(space.high, np.float64)
        masks = np.isfinite(low) | np.isfinite(high)
        if masks.any() and (~masks).any() and set(low[masks]) <= {0.0} and set(high[masks]) <= {1.0} \
                and np.isneginf(low[~masks]).all() and np.isposinf(high[~masks]).all():
            # unbounded observations with 0/1 mask entries (neighbour slots, received flags)
            return (f"`Box(-inf, inf, {tuple(space.shape)}, {space.dtype})`, "
                    f"{int(masks.sum())} mask entries in [0, 1]")
        return f"`Box({_fmt_bound(space.low)}, {_fmt_bound(space.high)}, {tuple(space.shape)}, {space.dtype})`"
    return f"`{space}`"


def attribute_docs(cls) -> dict[str, str]:
    """``name -> description`` of a numpy-style ``Attributes`` section (``Q, R`` gives both)."""
    doc = inspect.getdoc(cls) or ""
    if "Attributes" not in doc:
        return {}
    body = doc.split("Attributes", 1)[1].split("\n", 2)[2]
    out, names, desc = {}, [], []

    def flush():
        for n in names:
            out[n] = " ".join(desc).strip()

    for line in body.splitlines():
        if line and not line.startswith(" "):
            flush()
            names, desc = [n.strip() for n in line.split(":")[0].split(",")], []
        elif line.strip():
            desc.append(line.strip())
    flush()
    return {k: _DEV_NOTE.sub("", v) for k, v in out.items()}


def _cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def arguments_table(env_cls) -> list[str]:
    from dobs_envs.envs.options import EnvOptions

    docs = attribute_docs(EnvOptions)
    extra = attribute_docs(env_cls.Options) if env_cls.Options is not EnvOptions else {}
    rows = ["| argument | default | meaning |", "|---|---|---|"]
    for name, default in env_cls.valid_options().items():
        meaning = extra.get(name) or docs.get(name) or "see Arguments above"
        rows.append(f"| `{name}` | `{default!r}` | {_cell(meaning)} |")
    return rows


def sections(doc: str) -> tuple[str, list[tuple[str, str]]]:
    """The docstring's summary line and its ``## Title`` sections."""
    parts = SECTION.split(doc)
    summary = parts[0].strip()
    return summary, [(parts[i].strip(), parts[i + 1].strip("\n")) for i in range(1, len(parts), 2)]


def env_page(entry) -> str:
    import gymnasium as gym

    import dobs_envs  # noqa: F401  (registers the ids)

    module = importlib.import_module(entry.module)
    mod_name = entry.module.rsplit(".", 1)[1]
    mod_path, cls_name = entry.entry_point.split(":")
    env_cls = getattr(importlib.import_module(mod_path), cls_name)
    summary, secs = sections(inspect.getdoc(env_cls))
    pe = module.parallel_env()
    agents = pe.possible_agents
    genv = gym.make(entry.gym_id)
    lines = [f"# {mod_name}", "", _DEV_NOTE.sub("", summary), "",
             "| | |", "|---|---|",
             f"| PettingZoo | `from dobs_envs import {mod_name}`; `{mod_name}.parallel_env()` |",
             f"| Gymnasium id | `gym.make(\"{entry.gym_id}\")` |",
             f"| agents | {len(agents)}: `{agents[0]}` ... `{agents[-1]}` |",
             f"| default system | {_cell(entry.default_scenario)} |",
             f"| horizon | {entry.t_end:g} s ({genv.spec.max_episode_steps} control steps of "
             f"{pe.unwrapped.control_period:g} s) |"]
    for a in agents:
        lines.append(f"| `{a}` action / observation | {fmt_space(pe.action_space(a))} / "
                     f"{fmt_space(pe.observation_space(a))} |")
    lines += [f"| centralised action (`gym.make`) | {fmt_space(genv.action_space)} |",
              f"| centralised observation (`gym.make`) | {fmt_space(genv.observation_space)} |", "",
              "The spaces above are read from the environments with their default arguments when "
              "this page is built.", ""]
    pe.close()
    genv.close()
    for title, body in secs:
        lines += [f"## {title}", "", "```{eval-rst}", _DEV_NOTE.sub("", inspect.cleandoc(body)), "```", ""]
        if title == "Arguments":
            lines += ["Every argument, its default and its meaning:", ""] + arguments_table(env_cls) + [""]
    lines += ["## API", "", "```{eval-rst}", f".. autoclass:: {entry.entry_point.replace(':', '.')}",
              "   :no-index:", "```", ""]
    return "\n".join(lines)


def budgets_table() -> str:
    """The benchmark's budgets (:data:`agents.benchmark.plan.BUDGETS`) as a Markdown table."""
    from agents.benchmark.plan import AGENTS, BUDGETS

    rows = ["| budget | training runs per agent | evaluation episodes | agents: environment steps per run |",
            "|---|---|---|---|"]
    for name, b in BUDGETS.items():
        agents = ", ".join(f"{AGENTS[a].label} {n:,}" for a, n in b["agents"].items())
        rows.append(f"| `{name}` | {b['seeds']} | {b['episodes']} | {_cell(agents)} |")
    return "\n".join(rows) + "\n"


def _write(path: str, text: str) -> None:
    if not os.path.exists(path) or open(path).read() != text:  # unchanged pages are not rebuilt
        with open(path, "w") as f:
            f.write(text)


def generate(app) -> None:
    from dobs_envs.registry import ENVIRONMENTS

    _write(os.path.join(app.srcdir, "_generated_budgets.md"), budgets_table())
    out = os.path.join(app.srcdir, "environments")
    os.makedirs(out, exist_ok=True)
    for entry in ENVIRONMENTS.values():
        _write(os.path.join(out, entry.module.rsplit(".", 1)[1] + ".md"), env_page(entry))


def setup(app):
    app.connect("builder-inited", generate)
    return {"version": "1", "parallel_read_safe": True}
