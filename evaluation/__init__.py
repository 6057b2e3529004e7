"""Benchmarks of learned body models: one subpackage per benchmark on one small core (evaluation/core/).

levels (where is my body?), robustness (noise and broken sensors, open and closed loop), reaching, adaptation
(marker shift, Jupiter gravity), self_recognition (is this me?), and report (one page of every latest run).
A benchmark registers itself with one line in `registry.py`; the CLI's `evaluate` group is built from there.
"""
