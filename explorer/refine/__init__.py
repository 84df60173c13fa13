"""Sensor refinement: differentiable sensor models and their adjustment to control and tie points.

- :mod:`explorer.refine.corrections` -- image-space corrections of an RPC (shift, affine, poly2);
- :mod:`explorer.refine.torch_rpc` -- the RPC's ground to image in torch (float64), autograd Jacobians;
- :mod:`explorer.refine.bundle` -- Levenberg-Marquardt bundle adjustment with a robust loss (Schur
  complement over the ground points), sigma0 and covariances;
- :mod:`explorer.refine.adjust` -- :func:`refine_images`, the report and its files;
- :mod:`explorer.refine.fold` -- the correction folded into an RPC file;
- :mod:`explorer.refine.points_io` -- control/check/tie point CSV files.

torch is imported only by :mod:`explorer.refine.torch_rpc` (when an adjustment runs), never by
``import explorer`` nor by this package.
"""
