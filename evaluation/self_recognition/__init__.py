"""Self-recognition, "is this me?": the benchmark (benchmark.py), its babbling streams (streams.py), ROC, tables and
plots (report.py)."""

from bodyschema.evaluation.self_recognition.benchmark import SelfRecognitionConfig, run_self_recognition

__all__ = ["SelfRecognitionConfig", "run_self_recognition"]
