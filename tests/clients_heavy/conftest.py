"""Heavy clients (RLlib, BenchMARL, and the JAX libraries gymnax, JaxMARL, rejax): their pins (ray[rllib]
2.60 needs gymnasium 1.2.2, BenchMARL torchrl < 0.12, gymnax gymnasium < 1.4) conflict with the main test environment, so this directory is left
out of the main suite (``norecursedirs`` in pyproject.toml) and run by ``.ci/run`` in its own
virtual environment (``.ci/venv-clients``, see ``.ci/clients-heavy.txt``):

    python -m pytest -q tests/clients_heavy

The imports below fail loudly when the clients are missing: these tests never skip."""
import ray  # noqa: F401
import benchmarl  # noqa: F401
