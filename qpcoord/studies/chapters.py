"""The chapters of a reproduction report and which example scripts belong to each."""

from __future__ import annotations

__all__ = ["CHAPTERS", "SCRIPT_CHAPTERS", "STANDALONE_SCRIPTS"]

#: Chapters in report order, with their titles.
CHAPTERS: dict[str, str] = {
    "core": "Core: strict priorities as QP stacks",
    "4": "Chapter 4: periodicity of redundancy resolution",
    "5": "Chapter 5: potentials, limit cycles and hierarchies",
    "6": "Chapter 6: the dual-stage delay line",
    "A": "Appendix A: shoulder muscle-force sharing",
    "B": "Appendix B: blade flexure",
    "C": "Appendix C: piezo hysteresis (Preisach)",
}

#: File-name prefix of an example script → its chapter; the first matching prefix wins
#: (so the specific ``ch6_flexure`` comes before ``ch6_``). Scripts matching none are
#: listed in the report as not run.
SCRIPT_CHAPTERS: tuple[tuple[str, str], ...] = (
    ("ch6_flexure", "B"),
    ("sweep_ddl", "6"),
    ("ch4_", "4"),
    ("ch5_", "5"),
    ("ch6_", "6"),
    ("appA_", "A"),
    ("appB_", "B"),
    ("appC_", "C"),
    ("core_", "core"),
    ("panda_", "core"),
    ("talos_", "core"),
    ("solo12_", "core"),
    ("bimanual", "core"),
    ("sweep_", "core"),
)

#: Example scripts outside the reproduction: a public benchmark with its own data and its own
#: evaluation (``examples/hdd_benchmark.py --data DIR``), run by hand, not by
#: ``qpcoord reproduce`` (which neither runs nor lists them as unmapped).
STANDALONE_SCRIPTS: tuple[str, ...] = ("hdd_benchmark",)
