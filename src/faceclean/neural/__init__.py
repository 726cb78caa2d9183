"""The only place torch is imported: the recurrent cleaner, its losses, training, export.

Nothing outside this subpackage imports it; the CLI imports it inside ``run``.
"""
