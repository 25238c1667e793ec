"""Experiments: what drives a simulated world rather than builds one — the in-process runner,
the Gymnasium/PettingZoo environments, the source-seeking benchmark and the demo
(docs/architecture.md, "Layers")."""
