"""Occlusion polynomial texture maps (occlusion PTMs) for pipelines (python/src/lib.rs)."""
from os import PathLike
from typing import Literal, Optional, Sequence, Union

import numpy as np
import numpy.typing as npt

__version__: str

_Path = Union[str, PathLike[str]]
_Floats = Union[float, npt.ArrayLike]

class Ptm:
    """An occlusion PTM: per texel the coefficients of K = link(p(u, v)) in a polynomial basis."""

    def __init__(
        self,
        basis: Literal["ptm6", "ptm11"],
        coefficients: npt.ArrayLike,
        tile: tuple[float, float] = (1.0, 1.0),
        link: Literal["identity", "logistic"] = "identity",
        uv: Literal["projected", "hemispherical"] = "projected",
        coverage: Optional[npt.ArrayLike] = None,
        mips: Optional[Sequence[npt.ArrayLike]] = None,
    ) -> None: ...
    @property
    def basis(self) -> str: ...
    @property
    def link(self) -> str: ...
    @property
    def uv(self) -> str: ...
    @property
    def width(self) -> int: ...
    @property
    def height(self) -> int: ...
    @property
    def tile(self) -> tuple[float, float]: ...
    @property
    def monomials(self) -> list[str]: ...
    @property
    def coefficients(self) -> npt.NDArray[np.float32]:
        """(terms, height, width), a copy."""
    @property
    def coverage(self) -> Optional[npt.NDArray[np.float32]]:
        """(height, width), or None when every texel is fully covered."""
    @property
    def mips(self) -> list[npt.NDArray[np.float32]]:
        """MIP levels 1, 2, … to 1×1, each (terms, h, w); empty when the file has none."""
    @property
    def metadata(self) -> dict[str, object]:
        """Every header attribute (str, int, float or tuple)."""
    @property
    def layout(self) -> Optional[str]:
        """"channels" or "rgba" as loaded (the CLI's --layout names); None when built from arrays."""
    def eval_xy(self, lx: _Floats, ly: _Floats) -> npt.NDArray[np.float32]:
        """K for the projected light direction (lx, ly) = (l·T, l·B) (T = +X, B = +Y), not the
        file's (u, v): the file's (u, v) map (e.g. hemispherical) and link are applied here.
        Numbers → (height, width); N lights → (N, height, width)."""
    def eval(self, u: _Floats, v: _Floats) -> npt.NDArray[np.float32]:
        """Deprecated (FutureWarning on every call site): eval_xy under its old name; its
        arguments are the projected (lx, ly), not the file's (u, v)."""
    def eval_dir(self, l: npt.ArrayLike) -> npt.NDArray[np.float32]:
        """K for unit directions towards the light: (3,) → (height, width); (N, 3) → (N, height, width)."""
    def save(
        self, path: _Path, half: bool = False, layout: Literal["channels", "rgba"] = "channels"
    ) -> list[str]:
        """Writes the PTM; returns the files written. layout: the CLI's --layout names;
        "single" (the old name of "channels") raises ValueError naming "channels"."""

def load(path: _Path) -> Ptm:
    """Loads a PTM in either layout (the PTM EXR, or the renderer layout by a part or its stem)."""
