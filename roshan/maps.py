"""Land-cover maps: the FireSPIN cell-class table, the bundled CLC+ maps, GeoTIFF loading and cropping.

A map is a 2-D grid of cell-class ids (docs/model/fire.md §2 and §10): row 0 is the northern edge, each
cell one raster pixel. Maps come from single-band GeoTIFF crops of the Copernicus CLC+ Backbone raster
(10 m pixels, class ids 1-11, 254 = outside area, 255 = no data), or from the synthetic uniform map
(all cells of class 16, GENERIC_UNBURNED).

Unlike the reference simulator, which feeds raster values straight into the grid and crashes on
unexpected ones, :func:`read_geotiff` validates everything up front and raises :class:`MapError` with
a message that names the file and the reason.
"""

from __future__ import annotations

import difflib
import math
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import rasterio
import rasterio.warp
import rasterio.windows
from rasterio.crs import CRS
from rasterio.errors import CRSError, NotGeoreferencedWarning, RasterioError, WindowError

from roshan.io import refuse_overwrite
from roshan.memory import check_fits

__all__ = [
    "BURNED",
    "BURNING",
    "CLASSES",
    "FLOODED",
    "GENERIC_UNBURNED",
    "MAPS_DIR",
    "OUTSIDE_AREA",
    "OUTSIDE_GRID",
    "SEALED",
    "VALID_MAP_CLASSES",
    "WATER",
    "CellClass",
    "LandCoverMap",
    "MapError",
    "bundled_map_path",
    "bundled_maps",
    "check_drone_map",
    "class_arrays",
    "class_histogram",
    "crop_map",
    "describe_map",
    "ignitable_fraction",
    "initial_fire_count",
    "load_map",
    "read_geotiff",
    "uniform_map",
]

MAPS_DIR = Path(__file__).resolve().parent / "data" / "maps"

# Special cell-state ids (docs/model/fire.md §2; the code numbering, not the thesis numbering).
OUTSIDE_GRID, SEALED, WATER, BURNING, BURNED, FLOODED, OUTSIDE_AREA, GENERIC_UNBURNED = 0, 1, 10, 12, 13, 14, 15, 16

# Ids a map raster may contain once 254/255/nodata have been remapped: the 11 CLC+ classes, outside area
# and the uniform-map class. 0 and the dynamic states 12..14 are never valid in a raster.
VALID_MAP_CLASSES = (1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 15, 16)

# CLC+ product codes that mean "no land-cover information": both become OUTSIDE_AREA (non-flammable).
_CLC_OUTSIDE_AREA, _CLC_NO_DATA = 254, 255
_UNGEOREFERENCED_CELL_SIZE = 10.0  # the config cell_size of the reference
_MAX_LISTED_VALUES = 12  # keep error messages readable for badly wrong rasters
_EXPECTED = "expected 1-11, 15, 16 (254/255 = outside area/no data)"


class MapError(ValueError):
    """A map could not be found, read or validated; the message names the file (or map) and the reason."""


@dataclass(frozen=True)
class CellClass:
    """Per-class fire parameters (docs/model/fire.md §2.1).

    Attributes:
        id: Cell-state id (index into :data:`CLASSES`).
        name: Human-readable class name.
        is_ignitable: Whether a cell in this state may be ignited.
        tau_ign: Ignition delay (s of cumulative particle exposure).
        tau_burn: Nominal burning duration (s).
        n_conv: Convection particles emitted over the nominal burning duration.
        n_rad: Radiation particles emitted over the nominal burning duration.
        lr_min: Lower bound of the radiation length scale (m).
        lr_max: Upper bound of the radiation length scale (m).
        sf0_mean: Mean no-wind radiation spread rate (m/s).
        sf0_std: Standard deviation of the no-wind radiation spread rate (m/s).
        colour: Display colour (R, G, B), 0..255.
    """

    id: int
    name: str
    is_ignitable: bool
    tau_ign: float
    tau_burn: float
    n_conv: int
    n_rad: int
    lr_min: float
    lr_max: float
    sf0_mean: float
    sf0_std: float
    colour: tuple[int, int, int]


_C = CellClass
# Reference values of docs/model/fire.md §2.1 verbatim (including the unused tau values of states 14 and 16).
CLASSES: tuple[CellClass, ...] = (
    _C(0, "Outside grid", False, 0.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, (0, 0, 0)),
    _C(1, "Sealed", True, 750.0, 15000.0, 1000, 55, 9.0, 10.0, 0.1, 0.0075, (100, 100, 100)),
    _C(2, "Woody needle-leaved trees", True, 300.0, 3600.0, 80, 6, 9.0, 10.0, 0.1, 0.025, (0, 230, 0)),
    _C(3, "Woody broadleaved deciduous trees", True, 270.0, 3600.0, 60, 6, 9.0, 10.0, 0.1, 0.025, (0, 150, 0)),
    _C(4, "Woody broadleaved evergreen trees", True, 330.0, 3600.0, 100, 6, 9.0, 10.0, 0.1, 0.025, (0, 255, 0)),
    _C(5, "Low-growing woody plants", True, 120.0, 720.0, 40, 4, 9.0, 10.0, 0.1, 0.025, (105, 76, 51)),
    _C(6, "Permanent herbaceous", True, 100.0, 360.0, 20, 2, 9.0, 10.0, 0.1, 0.025, (250, 218, 94)),
    _C(7, "Periodically herbaceous", True, 100.0, 360.0, 20, 2, 9.0, 10.0, 0.1, 0.025, (240, 230, 140)),
    _C(8, "Lichens and mosses", True, 100.0, 240.0, 10, 3, 9.0, 10.0, 0.1, 0.025, (255, 153, 204)),
    _C(9, "Non- and sparsely vegetated", False, 0.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, (194, 178, 128)),
    _C(10, "Water", False, -1.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, (50, 90, 255)),
    _C(11, "Snow and ice", False, -1.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, (0, 255, 255)),
    _C(12, "Generic burning", False, -1.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, (255, 0, 0)),
    _C(13, "Generic burned", False, -1.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, (42, 42, 42)),
    _C(14, "Generic flooded", False, 10.0, 160.0, 10, 4, 9.0, 10.0, 0.1, 0.025, (77, 187, 230)),
    _C(15, "Outside area", False, 0.0, 0.0, 0, 0, 0.0, 0.0, 0.0, 0.0, (25, 25, 25)),
    _C(16, "Generic unburned", True, 10.0, 160.0, 10, 4, 5.0, 50.0, 0.1, 0.025, (50, 190, 75)),
)
del _C


def class_arrays() -> dict[str, np.ndarray]:
    """Return the class table as one array per field, indexed by class id (for kernel uploads).

    Returns:
        A dict with keys ``is_ignitable`` (bool), ``tau_ign``, ``tau_burn``, ``lr_min``, ``lr_max``,
        ``sf0_mean``, ``sf0_std`` (float32), ``n_conv``, ``n_rad`` (int32), each of shape (17,), and
        ``colour`` (uint8, shape (17, 3)).
    """
    arrays: dict[str, np.ndarray] = {"is_ignitable": np.array([c.is_ignitable for c in CLASSES], dtype=bool)}
    for key in ("tau_ign", "tau_burn", "lr_min", "lr_max", "sf0_mean", "sf0_std"):
        arrays[key] = np.array([getattr(c, key) for c in CLASSES], dtype=np.float32)
    for key in ("n_conv", "n_rad"):
        arrays[key] = np.array([getattr(c, key) for c in CLASSES], dtype=np.int32)
    arrays["colour"] = np.array([c.colour for c in CLASSES], dtype=np.uint8)
    return arrays


@dataclass(frozen=True, eq=False)  # eq=False: element-wise array comparison has no single truth value
class LandCoverMap:
    """An immutable grid of cell-class ids plus its georeferencing.

    ``classes`` is coerced on construction to a read-only, C-contiguous int32 copy and validated: it must
    be 2-D, non-empty and contain only ids from :data:`VALID_MAP_CLASSES`.

    Attributes:
        name: Bundled map name, ``"uniform"``, or the file stem.
        classes: (rows, cols) int32 class ids; row 0 is the northern edge.
        cell_size: Cell edge length in metres.
        crs: CRS as a string (e.g. ``"EPSG:3035"``), or None when not georeferenced.
        transform: Affine 6-tuple (a, b, c, d, e, f) mapping (col, row) to CRS coordinates, or None.
        source: File the map was read from, or None.
        is_uniform: True for the synthetic uniform map (config tau values apply, docs/model/fire.md §2.2).
    """

    name: str
    classes: np.ndarray
    cell_size: float
    crs: str | None
    transform: tuple | None
    source: Path | None
    is_uniform: bool = False

    def __post_init__(self) -> None:
        # Frozen dataclass: object.__setattr__ is the sanctioned way to normalise fields in __post_init__.
        object.__setattr__(self, "classes", _coerce_classes(self.name, self.classes))
        if not (math.isfinite(self.cell_size) and self.cell_size > 0):
            raise MapError(f"{self.name}: cell size must be a positive number of metres, got {self.cell_size!r}")
        object.__setattr__(self, "cell_size", float(self.cell_size))

    def __repr__(self) -> str:
        return (
            f"LandCoverMap(name={self.name!r}, shape={self.shape}, cell_size={self.cell_size}, "
            f"crs={self.crs!r}, source={self.source!r}, is_uniform={self.is_uniform})"
        )

    @property
    def rows(self) -> int:
        """Number of cell rows (north to south)."""
        return int(self.classes.shape[0])

    @property
    def cols(self) -> int:
        """Number of cell columns (west to east)."""
        return int(self.classes.shape[1])

    @property
    def shape(self) -> tuple[int, int]:
        """(rows, cols)."""
        return self.rows, self.cols

    @property
    def height_m(self) -> float:
        """North-south extent in metres."""
        return self.rows * self.cell_size

    @property
    def width_m(self) -> float:
        """West-east extent in metres."""
        return self.cols * self.cell_size

    @property
    def area_m2(self) -> float:
        """Total area in square metres."""
        return self.height_m * self.width_m


def _coerce_classes(name: str, classes: np.ndarray) -> np.ndarray:
    """Validate a class grid and return a read-only C-contiguous int32 copy."""
    arr = np.asarray(classes)
    if arr.ndim != 2:
        raise MapError(f"{name}: class grid must be 2-D, got shape {arr.shape}")
    if arr.size == 0:
        raise MapError(f"{name}: empty map ({arr.shape[0]} rows x {arr.shape[1]} cols)")
    if not np.issubdtype(arr.dtype, np.integer):
        # Refuse to truncate 2.5 -> 2 silently; read_geotiff reports such values in detail.
        if not np.all(np.isfinite(arr)) or not np.all(arr == np.round(arr)):
            raise MapError(f"{name}: class ids must be whole numbers")
    bad = ~np.isin(arr, VALID_MAP_CLASSES)
    if bad.any():
        raise MapError(f"{name}: class values outside the CLC+ table: {_format_counts(arr[bad])}; {_EXPECTED}")
    out = np.array(arr, dtype=np.int32, order="C", copy=True)
    out.flags.writeable = False
    return out


def _format_value(value: float) -> str:
    """Format a raster value compactly: integral values without a decimal point."""
    v = float(value)
    if math.isfinite(v) and v.is_integer() and abs(v) < 1e15:
        return str(int(v))
    return f"{v:g}"


def _format_counts(values: np.ndarray) -> str:
    """List each distinct value with its cell count, e.g. ``0 (3 cells), 100 (1 cell)``."""
    uniq, counts = np.unique(values, return_counts=True)
    parts = [f"{_format_value(v)} ({n} cell{'s' if n != 1 else ''})" for v, n in zip(uniq, counts, strict=True)]
    if len(parts) > _MAX_LISTED_VALUES:
        parts = parts[:_MAX_LISTED_VALUES] + [f"... and {len(parts) - _MAX_LISTED_VALUES} more distinct values"]
    return ", ".join(parts)


# --------------------------------------------------------------------------------------------------
# Bundled maps and the uniform map
# --------------------------------------------------------------------------------------------------


def bundled_maps() -> list[str]:
    """Return the sorted names (without ``.tif``) of the maps shipped in ``roshan/data/maps``.

    Returns:
        Map names such as ``["15x15_Woods", ..., "Borkenberge"]``.
    """
    return sorted(p.stem for p in MAPS_DIR.glob("*.tif") if p.is_file())


def _bundled_key(spec: str) -> str:
    """Normalise a map name for case-insensitive lookup with an optional .tif/.tiff suffix."""
    key = spec.strip().lower()
    for suffix in (".tiff", ".tif"):
        if key.endswith(suffix):
            return key[: -len(suffix)]
    return key


def _find_bundled(spec: str) -> str | None:
    """Return the canonical bundled name matching ``spec``, or None."""
    index = {name.lower(): name for name in bundled_maps()}
    return index.get(_bundled_key(spec))


def _unknown_map_error(spec: str) -> MapError:
    """Build the error for a name that is neither a bundled map nor an existing file."""
    names = bundled_maps()
    by_key = {name.lower(): name for name in names}
    close = difflib.get_close_matches(_bundled_key(Path(spec).name), list(by_key), n=1, cutoff=0.4)
    hint = f"; did you mean {by_key[close[0]]!r}?" if close else ""
    return MapError(
        f"{spec}: not a bundled map and no such file; bundled maps: {', '.join(names) or '(none)'}, or 'uniform'{hint}"
    )


def bundled_map_path(name: str) -> Path:
    """Return the path of a bundled map.

    Args:
        name: Map name, case-insensitive, ``.tif`` optional (e.g. ``"borkenberge.tif"``).

    Returns:
        The absolute path of the GeoTIFF.

    Raises:
        MapError: If no bundled map has that name (the message suggests the closest one).
    """
    found = _find_bundled(name)
    if found is None:
        raise _unknown_map_error(name)
    return MAPS_DIR / f"{found}.tif"


def uniform_map(rows: int = 50, cols: int = 50) -> LandCoverMap:
    """Build the synthetic uniform map (docs/model/fire.md §2.2): every cell GENERIC_UNBURNED, 10 m cells.

    Args:
        rows: Number of rows (the config's ``uniform_ny``).
        cols: Number of columns (the config's ``uniform_nx``).

    Returns:
        A map with ``is_uniform=True``, name ``"uniform"`` and no georeferencing.

    Raises:
        MapError: If rows or cols is not a positive integer.
    """
    if int(rows) != rows or int(cols) != cols or rows < 1 or cols < 1:
        raise MapError(f"uniform: rows and cols must be positive integers, got {rows} x {cols}")
    check_fits(f"the uniform map of {int(rows):,} x {int(cols):,} cells", int(rows) * int(cols) * 4,
               ["smaller map.uniform_rows / map.uniform_cols"])
    grid = np.full((int(rows), int(cols)), GENERIC_UNBURNED, dtype=np.int32)
    return LandCoverMap("uniform", grid, _UNGEOREFERENCED_CELL_SIZE, None, None, None, is_uniform=True)


def load_map(spec: str | Path | None, band: int | None = None, rows: int = 50, cols: int = 50) -> LandCoverMap:
    """Load a map by name or path.

    Resolution order: ``"uniform"``/``""``/None -> :func:`uniform_map`; a bare bundled name
    (case-insensitive, ``.tif`` optional, no directory part) -> the bundled GeoTIFF; otherwise a path.

    Args:
        spec: ``"uniform"``, a bundled map name, or a GeoTIFF path.
        band: 1-based band to read from a multi-band file (single-band files need none).
        rows: Rows of the uniform map (ignored otherwise).
        cols: Columns of the uniform map (ignored otherwise).

    Returns:
        The loaded map.

    Raises:
        MapError: For an unknown name (listing the bundled maps and the closest match) or an invalid file.
    """
    text = "" if spec is None else str(spec).strip()
    if text.lower() in ("", "uniform"):
        return uniform_map(rows, cols)
    # Only bare names are looked up among the bundled maps, so "some/dir/Borkenberge.tif" means that file.
    if Path(text).name == text:
        found = _find_bundled(text)
        if found is not None:
            return read_geotiff(MAPS_DIR / f"{found}.tif", band)
    path = Path(text).expanduser()
    if not path.exists():
        raise _unknown_map_error(text)
    return read_geotiff(path, band)


# --------------------------------------------------------------------------------------------------
# GeoTIFF reading
# --------------------------------------------------------------------------------------------------


def _select_band(path: Path, count: int, band: int | None) -> int:
    """Return the 1-based band to read, or raise if the choice is missing or out of range."""
    if count < 1:
        raise MapError(f"{path}: the file has no raster bands")
    if band is None:
        if count > 1:
            raise MapError(f"{path}: the file has {count} bands; choose one with --band N (1..{count})")
        return 1
    if not 1 <= band <= count:
        raise MapError(f"{path}: band {band} out of range; the file has {count} band(s) (1..{count})")
    return band


def _check_orientation(path: Path | str, t: rasterio.Affine) -> None:
    """Require a north-up, west-to-east, square-celled transform."""
    if t.b != 0 or t.d != 0:
        raise MapError(f"{path}: rotated or sheared raster (transform b={t.b}, d={t.d}); north-up expected")
    if t.e > 0:
        raise MapError(f"{path}: south-up raster (transform e={t.e} > 0); north-up expected (row 0 = north)")
    if t.a <= 0 or t.e == 0:
        raise MapError(f"{path}: mirrored or degenerate transform (a={t.a}, e={t.e}); north-up expected")
    if not math.isclose(abs(t.a), abs(t.e), rel_tol=1e-6):
        raise MapError(f"{path}: non-square cells: {abs(t.a):g} wide x {abs(t.e):g} high; square cells expected")


def _metres_per_unit(path: Path, crs: CRS | None) -> float:
    """Return the CRS's linear unit in metres (1.0 when unknown); reject geographic CRSs."""
    if crs is None:
        return 1.0
    if crs.is_geographic:
        raise MapError(f"{path}: geographic CRS {crs.to_string()} (cells in degrees); reproject to metres first")
    try:
        return float(crs.linear_units_factor[1])
    except CRSError:
        return 1.0  # no unit information: assume metres like the CLC+ product


def _georeference(path: Path, src: rasterio.io.DatasetReader) -> tuple[float, tuple | None, str | None]:
    """Return (cell_size in metres, transform 6-tuple or None, CRS string or None) of an open dataset."""
    t = src.transform
    if t.is_identity:
        # GDAL reports the identity transform for files without georeferencing; use the config cell size.
        return _UNGEOREFERENCED_CELL_SIZE, None, src.crs.to_string() if src.crs else None
    _check_orientation(path, t)
    cell_size = abs(t.a) * _metres_per_unit(path, src.crs)
    return cell_size, tuple(t)[:6], src.crs.to_string() if src.crs else None


def _class_for_value(value: float, nodata: float | None) -> int | None:
    """Map one raster value to a class id: nodata/NaN/254/255 -> OUTSIDE_AREA, valid ids as-is, else None."""
    v = float(value)
    if math.isnan(v) or v in (_CLC_OUTSIDE_AREA, _CLC_NO_DATA) or (nodata is not None and v == nodata):
        return OUTSIDE_AREA
    if v.is_integer() and int(v) in VALID_MAP_CLASSES:
        return int(v)
    return None


def _to_class_ids(path: Path, data: np.ndarray, nodata: float | None) -> np.ndarray:
    """Validate raster values and convert them to an int32 class grid (see :func:`read_geotiff`)."""
    # Work on the distinct values (a handful for CLC+ data) instead of per-cell float conversions.
    uniq = np.unique(data)
    mapping = {float(v): _class_for_value(v, nodata) for v in uniq}
    unknown = [v for v, cid in mapping.items() if cid is None]
    if unknown:
        # Report fractional values first: they usually mean a continuous raster, not a class map.
        fractional = [v for v in unknown if math.isfinite(v) and not v.is_integer()]
        listed = fractional or unknown
        cells = data[np.isin(data, listed)]
        if fractional:
            raise MapError(f"{path}: non-integral values (class ids must be whole numbers): {_format_counts(cells)}")
        raise MapError(f"{path}: class values outside the CLC+ table: {_format_counts(cells)}; {_EXPECTED}")
    out = np.empty(data.shape, dtype=np.int32)
    for value, cid in mapping.items():
        out[np.isnan(data) if math.isnan(value) else data == value] = cid
    return out


def read_geotiff(path: str | Path, band: int | None = None) -> LandCoverMap:
    """Read and validate a land-cover GeoTIFF.

    Rules: the raster must be north-up with square cells (or carry no georeferencing at all, in which
    case 10 m cells are assumed); values must be whole numbers from :data:`VALID_MAP_CLASSES` after
    remapping 254 (outside area), 255 (no data), the file's nodata value and NaN to OUTSIDE_AREA (15).

    Args:
        path: GeoTIFF (or any GDAL-readable raster) path.
        band: 1-based band to read; required when the file has several bands.

    Returns:
        The map, named after the file stem.

    Raises:
        MapError: If the file is missing or unreadable, the band choice is missing or invalid, the
            transform is rotated, south-up or has non-square cells, the raster is empty, or it holds
            non-integral or unknown class values (each listed with its cell count).
    """
    path = Path(path)
    if not path.exists():
        raise MapError(f"{path}: file not found")
    try:
        with warnings.catch_warnings():
            # Ungeoreferenced files are handled explicitly in _georeference.
            warnings.simplefilter("ignore", NotGeoreferencedWarning)
            with rasterio.open(path) as src:
                band = _select_band(path, src.count, band)
                if src.height == 0 or src.width == 0:
                    raise MapError(f"{path}: empty raster ({src.height} rows x {src.width} cols)")
                cell_size, transform, crs = _georeference(path, src)
                nodata = src.nodatavals[band - 1]
                data = src.read(band)
    except (RasterioError, OSError) as exc:
        raise MapError(f"{path}: not a readable raster ({exc})") from exc
    classes = _to_class_ids(path, data, nodata)
    return LandCoverMap(path.stem, classes, cell_size, crs, transform, path, is_uniform=False)


# --------------------------------------------------------------------------------------------------
# Summaries
# --------------------------------------------------------------------------------------------------


def class_histogram(m: LandCoverMap) -> dict[int, int]:
    """Count the cells of each class present in a map.

    Args:
        m: The map.

    Returns:
        ``{class id: cell count}`` for the ids present, in ascending id order.
    """
    ids, counts = np.unique(m.classes, return_counts=True)
    return {int(i): int(n) for i, n in zip(ids, counts, strict=True)}


def ignitable_fraction(m: LandCoverMap) -> float:
    """Return the fraction of cells whose class can ignite (docs/model/fire.md §2.1, "ign?" column)."""
    ignitable = class_arrays()["is_ignitable"]
    return float(ignitable[m.classes].mean())


def initial_fire_count(num_cells: int, fire_percentage: float) -> int:
    """Fires the initial fire generator lights on a map of ``num_cells`` cells (docs/model/fire.md §11): the float32
    product, truncated, as the reference computes it."""
    return int(np.float32(num_cells) * np.float32(fire_percentage))


# The groundstation sits one cell inside a map corner (docs/model/agents.md §4.1): rows 1 and rows - 2 must be cells;
# several bases sit in distinct corners, so rows 1 and rows - 2 must differ.
MIN_DRONE_MAP_SIDE = 3
MIN_BASES_MAP_SIDE = 4


def check_explorer_map(m: LandCoverMap, num_explorers: int) -> None:
    """Refuse a map whose longer side cannot be split into one meander stripe per explorer (the planner level),
    with a MapError naming the map, the key and the most explorers it takes."""
    side = max(m.rows, m.cols)  # the stripes cut the longer side
    if num_explorers > side:
        raise MapError(f"map {m.name!r} ({m.rows} x {m.cols} cells): planner.num_explorers = {num_explorers} explorers "
                       f"cannot share its longer side of {side} cells (one meander stripe each); set "
                       f"planner.num_explorers to at most {side}, or use a larger map")


def check_drone_map(m: LandCoverMap, fire_percentage: float, fights_fire: bool, who: str, bases: int = 1) -> None:
    """Refuse a map on which ``who`` (an env's description) cannot run a meaningful episode, with a MapError naming
    the map and why: smaller than 3 x 3 cells (no cell for the groundstation), smaller than 4 x 4 with several
    ``bases`` (``drones.bases``: no distinct corners for them), and where the drones' objective is
    to put fires out (``fights_fire``), no cell that can burn, or too few cells for ``fire_percentage`` to light
    any fire. Without the refusal such episodes ended at once with nothing lit and counted as successes.

    ``fire_percentage == 0`` is allowed: a scene whose fires are lit by hand (``FireSim.ignite_cells``).
    """
    where = f"map {m.name!r} ({m.rows} x {m.cols} cells)"
    if m.rows < MIN_DRONE_MAP_SIDE or m.cols < MIN_DRONE_MAP_SIDE:
        raise MapError(f"{where} is too small for {who}: the groundstation sits one cell inside a corner, so a map "
                       f"needs at least {MIN_DRONE_MAP_SIDE} x {MIN_DRONE_MAP_SIDE} cells")
    if bases > 1 and min(m.rows, m.cols) < MIN_BASES_MAP_SIDE:
        raise MapError(f"{where} is too small for {who} with drones.bases = {bases}: the bases sit one cell inside "
                       f"distinct corners, so a map needs at least {MIN_BASES_MAP_SIDE} x {MIN_BASES_MAP_SIDE} cells; "
                       "set drones.bases = 1")
    if not fights_fire:
        return
    if ignitable_fraction(m) == 0.0:
        classes = ", ".join(f"{CLASSES[c].name} ({n})" for c, n in class_histogram(m).items())
        raise MapError(f"{where} has no cell that can burn (its cells: {classes}): {who} would have no fire to put "
                       "out; use a map with burnable land")
    cells = m.rows * m.cols
    if fire_percentage > 0 and initial_fire_count(cells, fire_percentage) == 0:
        need = math.ceil(1.0 / fire_percentage)
        while initial_fire_count(need, fire_percentage) == 0:
            need += 1
        least = math.ceil(1e4 / cells) / 1e4  # rounded up to 4 decimals: it must light one fire as written
        while initial_fire_count(cells, least) == 0:
            least += 1e-4
        raise MapError(f"{where} is too small for ignition.fire_percentage = {fire_percentage:g}: {cells} cells x "
                       f"{fire_percentage:g} lights no fire, so {who} would have nothing to put out; use a map of "
                       f"at least {need} cells or ignition.fire_percentage >= {least:.4g}")


def describe_map(m: LandCoverMap) -> str:
    """Describe a map in human-readable text.

    Args:
        m: The map.

    Returns:
        Several lines: name, source, rows x cols, size in metres, CRS, cell size, the class histogram
        (id, name, count, percent) and the ignitable fraction.
    """
    total = m.rows * m.cols
    source = str(m.source) if m.source else ("synthetic (uniform map)" if m.is_uniform else "in memory")
    lines = [
        f"Map:        {m.name}",
        f"Source:     {source}",
        f"Grid:       {m.rows} rows x {m.cols} cols = {total} cells",
        f"Size:       {m.height_m:.0f} m (N-S) x {m.width_m:.0f} m (W-E) = {m.area_m2 / 1e4:.2f} ha",
        f"CRS:        {m.crs or 'none (not georeferenced)'}",
        f"Cell size:  {m.cell_size:g} m",
        "Classes:",
    ]
    for cid, count in class_histogram(m).items():
        lines.append(f"  {cid:>3}  {CLASSES[cid].name:<34} {count:>9}  {100.0 * count / total:6.2f} %")
    lines.append(f"Ignitable:  {100.0 * ignitable_fraction(m):.2f} % of cells")
    return "\n".join(lines)


# --------------------------------------------------------------------------------------------------
# Cropping
# --------------------------------------------------------------------------------------------------


def _source_bounds(
    src: rasterio.io.DatasetReader, bounds: tuple[float, float, float, float], bounds_crs: str | None
) -> tuple[float, float, float, float]:
    """Return ``bounds`` expressed in the source raster's CRS."""
    west, south, east, north = (float(b) for b in bounds)
    if not (west < east and south < north):
        raise MapError(f"{src.name}: invalid bounds {bounds}; expected (west, south, east, north) with west < east")
    if bounds_crs is None:
        return west, south, east, north
    try:
        crs = CRS.from_user_input(bounds_crs)
    except CRSError as exc:
        raise MapError(f"{src.name}: unknown bounds CRS {bounds_crs!r} ({exc})") from exc
    if src.crs is None:
        raise MapError(f"{src.name}: raster has no CRS, cannot use bounds given in {bounds_crs}")
    if crs == src.crs:
        return west, south, east, north
    # densify so the transformed box encloses the (curved) image of the original box
    return rasterio.warp.transform_bounds(crs, src.crs, west, south, east, north, densify_pts=21)


def _pixel_window(src: rasterio.io.DatasetReader, bounds: tuple[float, float, float, float]) -> rasterio.windows.Window:
    """Return the whole-pixel window of ``bounds`` intersected with the raster; raise if it is empty."""
    try:
        w = rasterio.windows.from_bounds(*bounds, transform=src.transform)
    except WindowError as exc:
        raise MapError(f"{src.name}: cannot compute a window for bounds {bounds} ({exc})") from exc
    # Round edges (not offset + length separately) so bounds on pixel edges give exactly those pixels.
    row0, col0 = round(w.row_off), round(w.col_off)
    row1, col1 = round(w.row_off + w.height), round(w.col_off + w.width)
    r0, c0, r1, c1 = max(row0, 0), max(col0, 0), min(row1, src.height), min(col1, src.width)
    if r0 >= r1 or c0 >= c1:
        raise MapError(
            f"{src.name}: bounds {tuple(round(b, 3) for b in bounds)} lie outside the raster "
            f"{tuple(round(b, 3) for b in src.bounds)} or cover less than one pixel"
        )
    if (r0, c0, r1, c1) != (row0, col0, row1, col1):
        warnings.warn(f"{src.name}: bounds extend beyond the raster; cropping to the overlap", stacklevel=3)
    return rasterio.windows.Window(c0, r0, c1 - c0, r1 - r0)


def _window_transform(t: rasterio.Affine, window: rasterio.windows.Window) -> rasterio.Affine:
    """Return the transform of a whole-pixel window of a north-up raster.

    Written out instead of ``DatasetReader.window_transform`` because that one uses the ``*`` operator that
    affine >= 2.4 flags as pending-deprecated, which would leak warnings into every caller.
    """
    return rasterio.Affine(t.a, 0.0, t.c + window.col_off * t.a, 0.0, t.e, t.f + window.row_off * t.e)


def crop_map(
    src: str | Path,
    bounds: tuple[float, float, float, float],
    out: str | Path,
    bounds_crs: str | None = None,
    band: int | None = None,
    replace: bool = False,
) -> LandCoverMap:
    """Cut a window out of a (possibly huge) land-cover GeoTIFF and write it as a new GeoTIFF.

    Only the window is read, so this works on the ~100 GB pan-European CLC+ product.

    Args:
        src: Source raster path, or a bundled map's name (``35x36_Woods``).
        bounds: (west, south, east, north); in the raster's CRS unless ``bounds_crs`` is given.
        out: Output GeoTIFF path (parent directories are created).
        bounds_crs: CRS of ``bounds`` (e.g. ``"EPSG:4326"``, lon/lat order); transformed to the
            raster's CRS when it differs.
        band: 1-based band of a multi-band source (single-band sources need none).
        replace: overwrite an existing ``out``; without it an existing file is refused before anything is read.

    Returns:
        The cropped map, read back and validated by :func:`read_geotiff`.

    Raises:
        MapError: If the source is unreadable or not north-up with square cells, the bounds are invalid,
            outside the raster or smaller than a pixel, or the crop holds invalid class values.
        OutputError: If ``out`` exists and ``replace`` is not set.
    """
    src_path, out_path = Path(src), Path(out)
    if not src_path.exists():  # a bundled map's name, as every other command takes it (else the closest names)
        src_path = bundled_map_path(str(src))
    if out_path.exists() and out_path.resolve() == src_path.resolve():
        raise MapError(f"{src_path}: output path equals the source; choose another file")
    refuse_overwrite(out_path, "the cropped map", replace)
    try:
        with rasterio.open(src_path) as ds:
            band = _select_band(src_path, ds.count, band)
            if ds.transform.is_identity:
                raise MapError(f"{src_path}: raster is not georeferenced; cannot crop by coordinates")
            _check_orientation(src_path, ds.transform)
            window = _pixel_window(ds, _source_bounds(ds, bounds, bounds_crs))
            data = ds.read(band, window=window)
            profile = {
                "driver": "GTiff",
                "height": int(window.height),
                "width": int(window.width),
                "count": 1,
                "dtype": ds.dtypes[band - 1],
                "crs": ds.crs,
                "transform": _window_transform(ds.transform, window),
                "nodata": ds.nodatavals[band - 1],
                "compress": "deflate",
            }
        out_path.parent.mkdir(parents=True, exist_ok=True)
        with rasterio.open(out_path, "w", **profile) as dst:
            dst.write(data, 1)
    except (RasterioError, OSError) as exc:
        raise MapError(f"{src_path}: cropping to {out_path} failed ({exc})") from exc
    return read_geotiff(out_path)
