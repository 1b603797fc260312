"""Generic utilities of the project, private to it (no planning in here).

- :mod:`~planner._util.atomic`: atomic file writes that never follow a link;
- :mod:`~planner._util.textfile`: strict UTF-8, size-limited reading of text files;
- :mod:`~planner._util.sealed`: files sealed with a SHA-256 digest of all their bytes;
- :mod:`~planner._util.toml_lines`: the line of every key of a TOML document;
- :mod:`~planner._util.torch_threads`: a context manager for torch's thread count.

They live in :mod:`planner` because both the planner and the simulation use them and the
planner imports nothing of the simulation. Each is imported on its own (``import planner._util``
imports none of them, so torch is loaded only by :mod:`~planner._util.torch_threads`).
"""
