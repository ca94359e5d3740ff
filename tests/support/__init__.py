"""Shared problem builders and oracles of the test suite and the benchmarks.

Test modules, and the scripts they run in a child Python, import these (``from
support.oracle import lexicographic``; pytest puts ``tests/`` on the path through its
``conftest.py``), never a test module. The benchmarks put ``tests/`` on their path and
import the same way.

- :mod:`support.oracle`: the exact lexicographic reference (cvxpy + Clarabel per level).
- :mod:`support.families`: seeded stack families of the solver comparison and their references.
- :mod:`support.campaign`: seeded degenerate stacks judged against the reference.
- :mod:`support.hlsp`: the published hierarchical least-squares problems (``tests/data/hlsp``).
- :mod:`support.dumps`: stacks stored level by level in ``.npz`` files (``tests/data``).
- :mod:`support.stacks`: stacks that several tests share (random conflicting levels, a box
  vertex, no freedom left, ...).
- :mod:`support.native_ik`: the native IK step's robots, start configurations and one stack
  per task kind; :mod:`support.kernel_tasks`: the native task kernels' tasks on the Panda and
  Talos; :mod:`support.talos_balance`: Talos on both soles (support polygon, CoM band);
  :mod:`support.obstacle_ik`: the Panda's hand among seven obstacles (collision rows).
- :mod:`support.arrays`: writing behind a task's read-only arrays.
- :mod:`support.native_info`: the native engine's ``Solution.info`` by its definition.
- :mod:`support.native_engine`: whether the native engine is built (``needs_native``), a
  native solver of a compiled stack, and the comparison of its answers with the Python engine's.
- :mod:`support.published`: the benchmark scripts as modules; published stacks and their moves.
- :mod:`support.strategies`: hypothesis strategies of random stacks.
- :mod:`support.weighted`: the weighted QP's cost, condition number and comparison.
- :mod:`support.counting_malloc`: a child Python whose malloc calls are counted, and
  :mod:`support.malloc_counts`, what its scripts count them with.
- :mod:`support.pages`: the runnable snippets of the README and the pages of ``docs/``.
- :mod:`support.browser`: a headless Chromium (a viewer page opened offline, its
  screenshots), or the reason a test skips.
"""
