"""A calibration's human-readable outputs: the summary table, ``results.txt``, ``frames.csv`` (``writers``) and the
report's figures (``figures``); the writers' names are importable from here."""

from vical.calib.report.writers import (
    FRAMES_CSV_HEADER,
    UNCERTAINTY_NOTE,
    display_unit,
    frames_csv,
    report_pages,
    results_text,
    summary_table,
    weak_sigma_text,
    write_frames_csv,
    write_report,
    write_results_text,
)

__all__ = [
    "FRAMES_CSV_HEADER",
    "UNCERTAINTY_NOTE",
    "display_unit",
    "frames_csv",
    "report_pages",
    "results_text",
    "summary_table",
    "weak_sigma_text",
    "write_frames_csv",
    "write_report",
    "write_results_text",
]
