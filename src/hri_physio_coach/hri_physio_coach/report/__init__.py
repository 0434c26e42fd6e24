"""hri_physio_report: the figures, numbers and page of one recorded session (logic, no rclpy).

``make_report(path)`` reads a session folder, bag directory or ``.mcap`` file (also a bag whose
recorder was killed) and writes ``hr_session.png``, the fuzzy policy's figures, ``hrv.png``,
``report.json`` and ``report.html`` into the session folder. docs/REPORT.md explains them.
"""

from hri_physio_coach.report.bagdata import ReportError
from hri_physio_coach.report.build import ReportResult, make_report

__all__ = ["ReportError", "ReportResult", "make_report"]
