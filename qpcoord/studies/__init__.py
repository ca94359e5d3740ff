"""Tooling around the library: reproducing the thesis, reports, figures, sweeps, benchmarks.

==================  ==================================================================
module              holds
==================  ==================================================================
``reproduce``       ``qpcoord reproduce``: run the examples, gather their claims
``render``          the report's Markdown and self-contained HTML
``chapters``        the report's chapters and which scripts belong to each
``timing``          per-step timing tables of a run
``claims``          :func:`~qpcoord.studies.claims.claim`: one claims-table row
``criteria``        decision rules shared by scripts and tests (each can fail)
``files``           atomic JSON/text writers, the examples' text log
``figures``         matplotlib figures of the examples (written to files)
``sweep``           :func:`qpcoord.sweep`: one function over a grid, in parallel
``bench_stack``     the solver comparison (``qpcoord bench``)
``bench_ik``        the IK per-step benchmark against Pink (``qpcoord bench-ik``)
``demo``            ``qpcoord demo``
==================  ==================================================================

The top layer below the CLI: it may use every other package; none uses it.
"""
