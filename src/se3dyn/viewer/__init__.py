"""See the motion: a self-contained 3D viewer page and animated glTF export of results.

An opt-in layer on top of :class:`~se3dyn.results.Results` (the core never imports it):

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
  ground symbols at fixed nodes, the gravity direction.

Mesh files need ``trimesh`` and glTF export ``pygltflib`` (``pip install 'se3dyn[view]'``).
"""

from __future__ import annotations

from se3dyn.viewer.shapes import Part, Scene, ViewerError, build_scene, equivalent_box

__all__ = ["write_html", "html_page", "show", "export_gltf", "build_scene", "Scene", "Part",
           "ViewerError", "equivalent_box", "Viewer"]


def html_page(res, **kwargs) -> str:
    """The viewer page of ``res`` as a string; keyword arguments of :func:`write_html`."""
    from se3dyn.viewer.html import html_page as _page

    return _page(res, **kwargs)


def write_html(res, path, **kwargs):
    """Write the viewer page of ``res`` to ``path``; see :func:`se3dyn.viewer.html.write_html`."""
    from se3dyn.viewer.html import write_html as _write

    return _write(res, path, **kwargs)


def export_gltf(res, path, **kwargs):
    """Write ``res`` as an animated glTF 2.0 binary; see :func:`se3dyn.viewer.gltf.export_gltf`."""
    from se3dyn.viewer.gltf import export_gltf as _export

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
