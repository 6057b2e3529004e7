"""`bodyschema report`: one Markdown and one HTML page of every benchmark's latest run (page.py), its sections and
skipped files (sections.py), with Markdown → HTML by markdown-it-py with GitHub's heading anchors and embedded
images (markdown_html.py), reading only files inside each run's folder (confined.py)."""

from bodyschema.evaluation.report.page import ReportConfig, write_report

__all__ = ["ReportConfig", "write_report"]
