"""The ament index of an editable install (no rclpy): what setup.py's data_files install, laid out in a prefix.

``pip install .`` and ``colcon build`` install the package marker, package.xml, config/, launch/ and the
``ros2 run`` executables under their prefix; ``pip install -e .`` installs none of them. ``gyro-sim ros-index``
lays them out under a prefix (default: this interpreter's, e.g. the venv) as symlinks into the source
tree, so that ``AMENT_PREFIX_PATH=PREFIX ros2 run gyro_sim simulator`` finds the package.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Optional

#: the packages this distribution indexes (gyro_ctl is a package of its own for ``ros2 run``)
PACKAGES = ("gyro_sim", "gyro_ctl")
#: ``ros2 run`` executables: install path → script of the source tree
EXECUTABLES = {"lib/gyro_sim/simulator": "scripts/simulator", "lib/gyro_ctl/controller": "scripts/controller"}


def source_root() -> Optional[Path]:
    """The source tree this gyro_sim is imported from (an editable install), or None (an installed copy)."""
    root = Path(__file__).resolve().parents[2]
    return root if (root / "setup.py").is_file() and (root / "package.xml").is_file() else None


def layout(root: Path) -> dict[str, Path]:
    """Path under the prefix → file of the source tree at ``root``, as setup.py's data_files install them."""
    out = {f"share/ament_index/resource_index/packages/{p}": root / "resource" / p for p in PACKAGES}
    out["share/gyro_sim/package.xml"] = root / "package.xml"
    out["share/gyro_ctl/package.xml"] = root / "resource" / "gyro_ctl_manifest" / "package.xml"
    for sub, pattern in (("config", "*.yaml"), ("config", "*.json"), ("launch", "*.launch.py")):
        out.update({f"share/gyro_sim/{sub}/{f.name}": f for f in sorted((root / sub).glob(pattern))})
    out.update({dest: root / src for dest, src in EXECUTABLES.items()})
    return out


def _link(target: Path, path: Path) -> bool:
    """Make ``path`` a symlink to ``target`` (replacing what is there); False if it already was one."""
    if path.is_symlink() and Path(os.readlink(path)) == target:
        return False
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_symlink() or path.exists():
        path.unlink()
    path.symlink_to(target)
    return True


def _script(source: Path, path: Path) -> bool:
    """Write the executable ``path``: ``source`` with this interpreter in its ``#!`` line (as pip writes
    console scripts), so ``ros2 run`` starts it with the venv's Python whatever PATH says."""
    lines = source.read_text(encoding="utf-8").splitlines(keepends=True)
    text = f"#!{sys.executable}\n" + "".join(lines[1:] if lines and lines[0].startswith("#!") else lines)
    if path.is_file() and not path.is_symlink() and path.read_text(encoding="utf-8") == text:
        return False
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.is_symlink():
        path.unlink()
    path.write_text(text, encoding="utf-8")
    path.chmod(0o755)
    return True


def _stale(prefix: Path, root: Path, keep: set) -> list[Path]:
    """Symlinks under the prefix's gyro_sim/gyro_ctl share folders into ``root`` that ``keep`` does not hold
    (a config file since removed from the source tree)."""
    out = []
    for pkg in PACKAGES:
        for path in sorted((prefix / "share" / pkg).rglob("*")):
            if path.is_symlink() and Path(os.readlink(path)).is_relative_to(root) and path not in keep:
                out.append(path)
    return out


def install_index(prefix: Path, root: Optional[Path] = None) -> list[Path]:
    """Lay out the ament index of the source tree ``root`` (default: :func:`source_root`) under ``prefix``;
    idempotent. Data files are symlinks into the tree; executables are written (see :func:`_script`).
    Returns the paths made, changed or removed (stale links)."""
    root = Path(root or source_root() or "").resolve()
    if not (root / "package.xml").is_file():
        raise FileNotFoundError(f"{root}: not a gyro_sim source tree (no package.xml)")
    prefix = Path(prefix).absolute()
    files = {prefix / dest: src for dest, src in layout(root).items()}
    changed = _stale(prefix, root, set(files))
    for p in changed:
        p.unlink()
    for path, src in files.items():
        made = _script(src, path) if path.relative_to(prefix).as_posix() in EXECUTABLES else _link(src, path)
        if made:
            changed.append(path)
    return changed


__all__ = ["PACKAGES", "EXECUTABLES", "source_root", "layout", "install_index"]
