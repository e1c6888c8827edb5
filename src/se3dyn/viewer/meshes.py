"""Mesh files of visuals (STL, OBJ, glTF/GLB), read with trimesh (the ``[view]`` extra)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from se3dyn.viewer.errors import ViewerError

__all__ = ["find_mesh", "load_mesh"]


def find_mesh(file: str, dirs) -> Path | None:
    """The mesh file: ``file`` itself when absolute, else the first ``dir / file`` that exists."""
    p = Path(file).expanduser()
    if p.is_absolute():
        return p if p.is_file() else None
    for d in dirs:
        q = Path(d) / p
        if q.is_file():
            return q
    return None


def load_mesh(file: str, dirs, item: str) -> tuple[np.ndarray, np.ndarray]:
    """Read a triangle mesh.

    Parameters
    ----------
    file : str
        File name as given in the model (absolute, or relative to one of ``dirs``).
    dirs : sequence of Path
        Folders searched in order for a relative name.
    item : str
        The visual, for error messages.

    Returns
    -------
    vertices : ndarray, shape (nv, 3), float64
        In the file's units and frame (a glTF scene is flattened with its node transforms).
    faces : ndarray, shape (nf, 3), int64
        Triangles (vertex indices, counter-clockwise seen from outside).

    Raises
    ------
    ViewerError
        File not found (naming the folders searched), trimesh missing, unreadable or empty mesh.
    """
    path = find_mesh(file, dirs)
    if path is None:
        where = ", ".join(str(d) for d in dirs) or "."
        raise ViewerError(f"{item}: field 'file': expected an existing mesh file, got {file!r} "
                          f"(looked in {where})")
    try:
        import trimesh
    except ImportError:
        raise ViewerError(f"{item}: field 'file': mesh files need trimesh: pip install "
                          "'se3dyn[view]'") from None
    try:
        mesh = trimesh.load(str(path), force="mesh", process=False)
    except Exception as e:  # trimesh raises many kinds for a bad file
        raise ViewerError(f"{item}: field 'file': expected a readable STL, OBJ or glTF mesh, got "
                          f"{str(path)!r} ({type(e).__name__}: {e})".splitlines()[0]) from None
    V = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=float)
    F = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if V.ndim != 2 or V.shape[1:] != (3,) or F.ndim != 2 or F.shape[1:] != (3,) or not len(F):
        raise ViewerError(f"{item}: field 'file': expected a mesh with triangles, got "
                          f"{str(path)!r} ({len(F)} triangles)")
    if not np.all(np.isfinite(V)) or F.min() < 0 or F.max() >= len(V):
        raise ViewerError(f"{item}: field 'file': expected finite vertices and valid triangles, "
                          f"got {str(path)!r}")
    return V, F
