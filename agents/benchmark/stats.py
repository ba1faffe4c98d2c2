"""The benchmark's statistics: :mod:`agents.stats` (rliable's IQM, stratified bootstrap and probability of
improvement with the training run as the unit), found here too, their import path before they moved below the
benchmark and the tuning tools, which both use them."""
from ..stats import *  # noqa: F401,F403
from ..stats import __all__  # noqa: F401
