"""What the tests share, imported as ``helpers.<module>`` (``tests/`` is on pytest's
``pythonpath``; a subprocess or a Dask worker gets it through ``PYTHONPATH`` or ``sys.path``).

* ``experiments``: the repository's root, the shrunk experiments (``SMALL_OVERRIDES``,
  ``small_experiment``, the CLI's ``TINY``) and ``sets`` for ``--set`` arguments;
* ``images``: failed comparisons' images written to ``tests/_failures/``;
* ``synthetic``: synthetic shader inputs (no Mitsuba);
* ``port_checks``: the port's shared constants and checks (central differences, the NumPy
  reference, hand-made pools);
* ``gl``: the port against OpenGL (llvmpipe) and its thresholds;
* ``drjit_toy``: a small Dr.Jit image model for the fitting engine;
* ``sweep_jobs``: job functions for the sweep tests' spawned Dask workers;
* ``preview_driver``: a script run by path that previews many experiments in one process.

No test module imports another test module: what two of them share lives here.
"""

from pathlib import Path

TESTS = Path(__file__).resolve().parent.parent
REPO = TESTS.parent
