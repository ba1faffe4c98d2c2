"""The paper's design layer (Lemma 2, observer gains, controller gains)."""
