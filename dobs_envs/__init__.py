"""dobs-envs: distributed-observer control benchmark (Cao & Yin)."""
__version__ = "0.1.0"
