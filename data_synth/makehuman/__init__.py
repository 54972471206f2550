"""Realistic head rigs from the MakeHuman head (CC0) and an artist's ARKit shapes (MIT).

The data files ship in ``data_synth/makehuman/data/`` with their licence notice (LICENSES.md)
and their documentation (README.md): ``makehuman_heads.npz`` (identity targets, bust) and
``makehuman_arkit.npz`` (52 ARKit shapes on the same vertices).
"""
