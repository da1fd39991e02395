"""Data with a known truth: the paper's Examples 1 and 2, the reproduction of its Section 5,
the withheld-effect cases the diagnosis is judged on, and the folder of shared measured records.
"""

from __future__ import annotations

from ._examples import ExampleData, example1, example2, example_data, shared_data_folder
from ._paper import ExampleRun, ExampleSetting, iteration_table, paper_report, run_example, write_figures
from ._withheld import ALL_EFFECTS, CATALOGUE, OUT_OF_CATALOGUE, Case, CaseSpec, case_specs, cases, make_case, simulate_true

__all__ = [
    "ALL_EFFECTS",
    "CATALOGUE",
    "Case",
    "CaseSpec",
    "ExampleData",
    "ExampleRun",
    "ExampleSetting",
    "OUT_OF_CATALOGUE",
    "case_specs",
    "cases",
    "example1",
    "example2",
    "example_data",
    "iteration_table",
    "make_case",
    "paper_report",
    "run_example",
    "shared_data_folder",
    "simulate_true",
    "write_figures",
]
