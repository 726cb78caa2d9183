"""The tuning page: a thin view over the library in a browser (STYLE.md item 14).

``faceclean ui take.csv`` (offline.py) and ``faceclean relay ... --ui`` (live.py) serve
the same page (static/) from server.py: one loopback port, a per-start token, the
pinned three.js and the report's face view. What the page chooses is a ``Tuning``
(tuning.py): the CLI's own words, checked by the one resolver, saved as the files the
CLI reads. Needs the optional extra ``ui`` (the ``websockets`` package).
"""
