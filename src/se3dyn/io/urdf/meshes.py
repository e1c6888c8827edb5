"""Where a URDF's mesh file is: ``package://NAME/rest`` looked up in the package
directories given, those of ``ROS_PACKAGE_PATH`` and the folders above the URDF file named
NAME; ``file://`` and absolute paths as they are; relative paths from the URDF's folder."""

from __future__ import annotations

import os
from pathlib import Path


def package_roots(package_dirs, urdf_path: str) -> list[Path]:
    """The folders searched for ``package://`` meshes, in order: ``package_dirs``, then
    ``ROS_PACKAGE_PATH``'s entries, then the URDF file's folder and those above it."""
    if isinstance(package_dirs, str | os.PathLike):
        package_dirs = [package_dirs]
    roots = [Path(p) for p in package_dirs]
    roots += [Path(p) for p in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if p]
    here = Path(urdf_path).resolve().parent
    return roots + [here, *here.parents]


def candidates(filename: str, urdf_path: str, roots: list[Path]) -> list[Path]:
    """The paths a mesh ``filename`` may be at, most likely first."""
    if filename.startswith("package://"):
        rest = filename[len("package://"):]
        pkg, _, sub = rest.partition("/")
        out = []
        for r in roots:
            out.append(r / pkg / sub)
            if r.name == pkg:  # the folder is the package itself
                out.append(r / sub)
        return list(dict.fromkeys(out))
    if filename.startswith("file://"):
        return [Path(filename[len("file://"):])]
    p = Path(filename)
    return [p] if p.is_absolute() else [Path(urdf_path).resolve().parent / p]


def resolve(filename: str, urdf_path: str, roots: list[Path]) -> tuple[Path | None, list[Path]]:
    """The mesh file found (or None) and the paths tried."""
    tried = candidates(filename, urdf_path, roots)
    for p in tried:
        if p.is_file():
            return p.resolve(), tried
    return None, tried
