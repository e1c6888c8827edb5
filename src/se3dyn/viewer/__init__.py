"""See the motion: a self-contained 3D viewer page and animated glTF export of results.

An opt-in layer on top of :class:`~se3dyn.results.results.Results` (the core never imports it):

* :func:`write_html` / :func:`html_page`: one HTML file with three.js inlined (nothing is fetched
  when it opens): play/pause, time scrubber, speed, loop, orbit/pan/zoom, node frames, traces of
  points, a channel plot synchronised with the time cursor; ``#t=SECONDS`` in the address opens
  it paused at that time. ``se3dyn view RESULTS [-o FILE.html]`` on the command line.
* :func:`show`: the same page inline in a Jupyter notebook (``Results.show()``).
* :func:`export_gltf`: glTF 2.0 binary (``.glb``) with one translation and one rotation channel
  per moving node (``se3dyn export RESULTS --gltf FILE.glb``).
* :func:`build_scene` (:mod:`se3dyn.viewer.shapes`): what is drawn. Visual shapes of the model
  (``ModelBuilder.visual``, ``visuals:`` in model files) or a default picture: bodies as boxes
  with the body's mass and inertia, joint glyphs on the joint axes, links from nodes to joints,
  ground symbols at fixed nodes, the gravity direction; marker triads and drive collars.

Mesh files need ``trimesh`` and glTF export ``pygltflib`` (``pip install 'se3dyn[view]'``).
"""

from __future__ import annotations

from se3dyn.viewer.errors import ViewerError
from se3dyn.viewer.shapes import Part, Scene, build_scene, equivalent_box

__all__ = ["write_html", "html_page", "show", "export_gltf", "build_scene", "Scene", "Part",
           "ViewerError", "equivalent_box", "Viewer"]


def check_motion(res) -> None:
    """Refuse results the viewer cannot draw (a damaged or crafted results file): times that
    are not finite or go backwards, frames with non-finite positions or with rotations that
    are not rotations (orthonormal, determinant +1).

    Raises
    ------
    ViewerError
        Naming the field, the node, the row and its time, and the value found.
    """
    import numpy as np

    from se3dyn.errors import _short_repr

    t = getattr(res, "t", None)
    H = getattr(res, "H", None)
    if not isinstance(t, np.ndarray) or not isinstance(H, np.ndarray):
        raise ViewerError(f"results: expected a Results (times t and frames H), got "
                          f"{_short_repr(res)}")
    if t.dtype.kind not in "iuf" or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
        bad = next((i for i in range(len(t)) if not np.isfinite(t[i])
                    or (i and t[i] < t[i - 1])), 0) if t.dtype.kind in "iuf" else 0
        raise ViewerError(f"results: field 't': expected finite times in increasing order, "
                          f"got {_short_repr(t[bad].item() if t.size else t)} at row {bad}")
    if H.ndim != 4 or H.shape[0] != len(t) or H.shape[2:] != (4, 4):
        raise ViewerError(f"results: field 'H': expected frames of shape ({len(t)}, nodes, 4, "
                          f"4), got shape {H.shape}")
    R, x = H[:, :, :3, :3], H[:, :, :3, 3]
    with np.errstate(invalid="ignore", over="ignore"):
        err = np.abs(np.einsum("nmji,nmjk->nmik", R, R) - np.eye(3)).max(axis=(2, 3))
        det = np.linalg.det(R) if R.size else np.ones(R.shape[:2])
    bad_x = ~np.all(np.isfinite(x), axis=2)
    bad_r = ~(err < 1e-6) | ~(det > 0)  # (NaN fails both)
    for what, mask, field in (("finite positions", bad_x, "position"),
                              ("rotations (orthonormal, determinant +1)", bad_r, "rotation")):
        if mask.any():
            i, j = (int(k) for k in np.argwhere(mask)[0])
            name = res.system.node_names[j] if j < len(res.system.node_names) else j
            got = " ".join(_short_repr(x[i, j] if field == "position" else R[i, j]).split())
            raise ViewerError(f"results: node {name!r}: field '{field}': expected {what}, got "
                              f"{got} at row {i} (t = {float(t[i]):g} s)")


def _check_path(path, suffixes: str) -> None:
    import os

    if not isinstance(path, str | os.PathLike):
        raise ViewerError(f"output: field 'path': expected a file name ({suffixes}), got "
                          f"{path!r}")


def html_page(res, **kwargs) -> str:
    """The viewer page of ``res`` as a string; keyword arguments of :func:`write_html`."""
    from se3dyn.viewer.html import html_page as _page

    check_motion(res)
    return _page(res, **kwargs)


def write_html(res, path, **kwargs):
    """Write the viewer page of ``res`` to ``path``; see :func:`se3dyn.viewer.html.write_html`."""
    from se3dyn.viewer.html import write_html as _write

    check_motion(res)
    _check_path(path, ".html")
    return _write(res, path, **kwargs)


def export_gltf(res, path, **kwargs):
    """Write ``res`` as an animated glTF 2.0 binary; see :func:`se3dyn.viewer.gltf.export_gltf`."""
    from se3dyn.viewer.gltf import export_gltf as _export

    check_motion(res)
    _check_path(path, ".glb or .gltf")
    return _export(res, path, **kwargs)


class Viewer:
    """The viewer page of a result, displayed inline by Jupyter (``_repr_html_``).

    Attributes
    ----------
    html : str
        The complete page.
    height : int
        Height of the inline frame (pixels).
    """

    def __init__(self, html: str, height: int = 520):
        self.html = html
        self.height = int(height)

    def _repr_html_(self) -> str:
        import html as _html

        return (f'<iframe srcdoc="{_html.escape(self.html, quote=True)}" '
                f'style="width:100%;height:{self.height}px;border:1px solid #ddd">'
                '</iframe>')

    def save(self, path) -> None:
        """Write the page to ``path``."""
        from pathlib import Path

        Path(path).write_text(self.html, encoding="utf-8")


def show(res, height: int = 520, **kwargs) -> Viewer:
    """The viewer of ``res`` for a Jupyter notebook: an object shown inline as an iframe
    (``srcdoc``, so it works without a server); keyword arguments of :func:`write_html`."""
    return Viewer(html_page(res, **kwargs), height=height)
