"""nvdiffrast's primitives on softvk.

:mod:`softvk.nvdiffrast.torch` is nvdiffrast's PyTorch module (``rasterize``, ``DepthPeeler``,
``interpolate``, ``antialias``, their contexts and helpers), so an nvdiffrast program runs with
one changed import::

    import softvk.nvdiffrast.torch as dr     # was: import nvdiffrast.torch as dr

This package imports nothing itself (torch is imported by ``softvk.nvdiffrast.torch`` only).
"""
