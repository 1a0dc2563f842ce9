"""SoftRas's soft rasterization, run by softvk's engine (``softvk.torch.soft_rasterize``)."""

__all__ = ["soft_rasterize"]


def soft_rasterize(face_vertices, textures, image_size=256, background_color=[0, 0, 0],
                   near=1, far=100, fill_back=True, eps=1e-3, sigma_val=1e-5,
                   dist_func="euclidean", dist_eps=1e-4, gamma_val=1e-4,
                   aggr_func_rgb="softmax", aggr_func_alpha="prod", texture_type="surface"):
    """Soft-rasterizes faces given in screen space (SPEC §2), differentiably.

    Args:
        face_vertices: [batch, F, 3, 3] corners in screen space (x, y in [-1, 1] across the
            image, depth).
        textures: [batch, F, R², 3] (``texture_type='surface'``) or [batch, F, 3, 3] per-corner
            colours (``'vertex'``).
        image_size: H = W in pixels.
        background_color: RGB behind the faces.
        near, far: depth range of the colour aggregation.
        fill_back: faces are double-sided.
        eps: background weight of the softmax colour aggregation.
        sigma_val: sharpness of the coverage (smaller is sharper).
        dist_func: ``'euclidean'``, ``'barycentric'`` or ``'hard'``.
        dist_eps: coverage below which a face is ignored.
        gamma_val: temperature of the softmax over depth.
        aggr_func_rgb: ``'softmax'`` or ``'hard'``.
        aggr_func_alpha: ``'prod'``, ``'sum'`` or ``'hard'``.
        texture_type: ``'surface'`` or ``'vertex'``.

    Returns:
        [batch, 4, image_size, image_size] RGBA, differentiable in ``face_vertices`` and
        ``textures``.
    """
    # Imported here so that the rest of the package (meshes, cameras, losses, files) works
    # without the engine.
    from ... import torch as engine

    return engine.soft_rasterize(face_vertices, textures, image_size, background_color,
                                 near, far, fill_back, eps, sigma_val, dist_func, dist_eps,
                                 gamma_val, aggr_func_rgb, aggr_func_alpha, texture_type)
