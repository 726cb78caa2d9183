"""Training and evaluation data: the real takes and their splits and chunks (dataset.py),
the simulated tracker artefacts that corrupt them (simulate.py), synthetic performers
(performer.py), and folders of rendered pairs (paired.py). numpy only: neural/ trains on
it, evaluation/ judges on it."""
