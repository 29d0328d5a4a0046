"""Regression cases: failures exported as self-contained files, re-run against a changed SUT.

This package sits above ``analysis`` (export reads a run's tables through it) and ``campaign``
(re-running a case builds its simulation as a run does); nothing below imports it.
"""

from hazardhunt.cases.export import export_cases, write_pytest_module
from hazardhunt.cases.regression import (
    VERDICTS,
    CaseError,
    RegressionResult,
    case_files,
    regress_case,
)

__all__ = [
    "VERDICTS",
    "CaseError",
    "RegressionResult",
    "case_files",
    "export_cases",
    "regress_case",
    "write_pytest_module",
]
