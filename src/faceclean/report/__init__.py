"""The self-contained HTML report: measures, curves per channel group, a 3D face view.

from faceclean import report
from faceclean.evaluation import comparison
report.write(comparison.compare(noisy, truth, ["one-euro", "kalman"]), "report.html")
"""

from faceclean.report.build import render, write

__all__ = ["render", "write"]
