"""What every package shares: atomic file output and strict JSON (:mod:`common.files`), rotations
and quaternions (:mod:`common.spatial`), value-list parsing (:mod:`common.parse`) and the project's
defaults (:mod:`common.defaults`).

``common`` is the bottom of the import graph: it imports NumPy and the standard library only, and
every other package may import it (``docs/architecture.md``).
"""
