"""File formats below the maps and the data sets: point clouds in and out.

Today: the PCD reader and writer (:func:`read_pcd`, :func:`write_pcd`, with PCL's LZF
codec) and the scan record (:class:`Scan`) every reader returns. The maps' exports
(``occgp/io/_export.py``) write PCD through here; :mod:`occgp.datasets` re-exports these
names where they were. docs/architecture.rst lists what moves here later (the OctoMap
formats, ``.npz`` files, the PLY and Open3D exports, the real-data readers).
"""

from ._pcd import lzf_decompress, read_pcd, write_pcd
from ._scan import Scan

__all__ = ["Scan", "read_pcd", "write_pcd", "lzf_decompress"]
