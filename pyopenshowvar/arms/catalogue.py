"""The arms shipped with the package, and :func:`load_arm` for a name or a file.

The catalogue is the ``data/*.toml`` files next to this module (one arm each, with its
source and licence noted); an entry's name is its file name without ``.toml``. Loading a
catalogue arm needs numpy only; a ``.urdf`` path needs the ``urdf`` extra (yourdfpy).
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources
from pathlib import Path

from .errors import UnknownArmError
from .files import load_toml
from .model import Arm

__all__ = ["arm_for_model_name", "catalogue", "load_arm"]

_DATA = "data"


def catalogue() -> list[str]:
    """Names of the catalogue arms, sorted."""
    root = resources.files(__package__).joinpath(_DATA)
    return sorted(p.name[: -len(".toml")] for p in root.iterdir() if p.name.endswith(".toml"))


@lru_cache(maxsize=64)
def _catalogue_arm(name: str) -> Arm:
    ref = resources.files(__package__).joinpath(_DATA, f"{name}.toml")
    with resources.as_file(ref) as path:
        return load_toml(path, key=name)


def load_arm(name_or_path: str | Path) -> Arm:
    """An arm by catalogue name (``"kr210_r2700_2"``) or from a ``.toml`` / ``.urdf`` file.

    Catalogue arms are cached and shared (they are immutable). Raises
    :class:`~.errors.UnknownArmError` for a name that is neither, and
    :class:`~.errors.ArmFileError` for a file that cannot be used.
    """
    text = str(name_or_path)
    key = text.lower().replace("-", "_").replace(" ", "_")
    if isinstance(name_or_path, str) and key in catalogue():
        return _catalogue_arm(key)
    path = Path(name_or_path)
    if path.suffix.lower() == ".urdf":
        from .urdf import load_urdf

        return load_urdf(path)
    if path.suffix.lower() == ".toml" or path.exists():
        return load_toml(path)
    raise UnknownArmError(
        f"no arm {text!r}: not in the catalogue ({', '.join(catalogue())}) and no such file"
    )


def _arm_type(model_name: str) -> str:
    """The arm type of a ``$MODEL_NAME[]`` text: its first word, without quotes and ``#``,
    upper case (``'"#KR16R2010-2 C4 FLR"'`` -> ``KR16R2010-2``); the rest names the
    controller and variant, which do not change the arm's geometry."""
    words = model_name.strip().strip('"').strip().lstrip("#").split()
    return words[0].upper() if words else ""


def arm_for_model_name(model_name: str) -> Arm | None:
    """The catalogue arm a controller's ``$MODEL_NAME[]`` names, or None if none does.

    Compared by arm type (the first word): a controller answering ``#KR6R900SIXX C4SR FLR``
    or ``#KR6R900SIXX`` is the KR 6 R900 sixx.
    """
    wanted = _arm_type(model_name)
    if not wanted:
        return None
    for name in catalogue():
        arm = _catalogue_arm(name)
        if arm.model_name and _arm_type(arm.model_name) == wanted:
            return arm
    return None
