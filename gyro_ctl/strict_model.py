"""The base of the validated, immutable parameter models (a scene and its parts, the controller's parameters)."""
from __future__ import annotations

from pydantic import BaseModel, ConfigDict

__all__ = ["StrictModel"]


class StrictModel(BaseModel):
    """A pydantic model that refuses unknown keys and is immutable once validated.

    Setting a field raises AttributeError with what to do instead: a validated copy with the change,
    ``scene.replace({"stators.2.current": 0.5})`` (the dotted key from the scene's top) or
    ``scene.replace(duration=5.0)`` (:meth:`gyro_sim.scenes.scene.Scene.replace`, docs/scenes.md). A copy made
    by pydantic's ``model_copy(update=...)`` is not validated; a run validates its scene again and refuses it
    with the usual one-line error."""

    # (the docstring under each field is its description: meaning and SI unit, in the API reference and JSON schema)
    model_config = ConfigDict(extra="forbid", frozen=True, use_attribute_docstrings=True)

    def __setattr__(self, name: str, value) -> None:
        cls = type(self).__name__
        how = (f"scene.replace({name}=...)" if cls == "Scene" else
               f"scene.replace({{'<path>.{name}': ...}}) with the dotted key from the scene's top, e.g. "
               "scene.replace({'stators.2.current': 0.5})")
        raise AttributeError(f"{cls}.{name} cannot be set: a scene and its parts are immutable once validated; make "
                             f"a validated copy with the change: {how} (docs/scenes.md)")

    def __delattr__(self, name: str) -> None:
        self.__setattr__(name, None)
