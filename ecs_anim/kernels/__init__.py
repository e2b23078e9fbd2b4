"""The tick's compiled kernels (numba, DESIGN §7): one module per system, over the store's arrays.

Each kernel writes its results in place and mirrors a numpy function of the package, which stays
as the reference the tests compare it with (to 1e-9 m). ``vec`` holds the scalar helpers they
share: 3-vectors as tuples, frames as tuples of their three axes.
"""
