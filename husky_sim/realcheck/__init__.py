"""Sim-to-real checks before a Husky trial, one feature: the configuration audit, the seeded
robustness sweep, `check` (audit + sweep -> verdict) and the replay of real recordings."""
