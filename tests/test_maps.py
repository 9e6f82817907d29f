"""Tests for roshan.maps: class table, bundled maps, GeoTIFF validation, summaries and cropping."""

from __future__ import annotations

import numpy as np
import pytest
import rasterio
import rasterio.io
import rasterio.warp
import rasterio.windows
from rasterio.transform import Affine

from roshan import maps
from roshan.maps import MapError

# docs/model/fire.md §10: class counts of the shipped maps.
BUNDLED = {
    "15x15_Woods": ((15, 15), {2: 219, 6: 6}),
    "21x21_Field": ((21, 21), {3: 30, 6: 233, 7: 178}),
    "35x36_Woods": ((35, 36), {1: 65, 2: 763, 3: 111, 6: 242, 7: 79}),
    "54x71_Woods": ((54, 71), {2: 2183, 3: 1619, 5: 6, 6: 26}),
    "81x129_Campsite": ((81, 129), {1: 1476, 2: 15, 3: 678, 5: 1, 6: 2556, 7: 5639, 9: 84}),
    "Borkenberge": (
        (481, 758),
        {1: 8604, 2: 148952, 3: 64977, 5: 14638, 6: 51368, 7: 58328, 9: 2402, 10: 15329},
    ),
}


def window_bounds(window, t):
    """(west, south, east, north) of a whole-pixel window of a north-up transform."""
    west, north = t.c + window.col_off * t.a, t.f + window.row_off * t.e
    return west, north + window.height * t.e, west + window.width * t.a, north


NORTH_UP = Affine(10.0, 0.0, 4_000_000.0, 0.0, -10.0, 3_000_000.0)


def write_tif(path, data, transform=NORTH_UP, crs="EPSG:3035", nodata=None):
    """Write a (bands, rows, cols) or (rows, cols) array as a GeoTIFF and return its path."""
    data = np.asarray(data)
    if data.ndim == 2:
        data = data[None]
    profile = {
        "driver": "GTiff",
        "count": data.shape[0],
        "height": data.shape[1],
        "width": data.shape[2],
        "dtype": data.dtype,
        "crs": crs,
        "transform": transform,
        "nodata": nodata,
    }
    with rasterio.open(path, "w", **profile) as dst:
        dst.write(data)
    return path


# ---------------------------------------------------------------- class table


def test_class_table_layout():
    assert [c.id for c in maps.CLASSES] == list(range(17))
    zero = maps.CLASSES[maps.OUTSIDE_GRID]
    assert not zero.is_ignitable and zero.colour == (0, 0, 0) and zero.tau_ign == zero.n_conv == zero.lr_max == 0
    ignitable = {c.id for c in maps.CLASSES if c.is_ignitable}
    assert ignitable == {1, 2, 3, 4, 5, 6, 7, 8, 16}
    assert maps.CLASSES[maps.SEALED].n_conv == 1000 and maps.CLASSES[maps.SEALED].sf0_std == 0.0075
    assert (maps.CLASSES[16].lr_min, maps.CLASSES[16].lr_max) == (5.0, 50.0)
    assert maps.CLASSES[maps.WATER].colour == (50, 90, 255)
    arrays = maps.class_arrays()
    assert arrays["colour"].shape == (17, 3) and arrays["n_rad"][2] == 6 and arrays["tau_burn"][6] == 360


# ---------------------------------------------------------------- bundled maps


def test_bundled_names():
    assert maps.bundled_maps() == sorted(BUNDLED)


@pytest.mark.parametrize("name", sorted(BUNDLED))
def test_bundled_map_matches_spec(name):
    m = maps.load_map(name)
    shape, hist = BUNDLED[name]
    assert m.name == name and m.shape == shape and (m.rows, m.cols) == shape
    assert maps.class_histogram(m) == hist
    assert m.classes.dtype == np.int32 and m.classes.flags.c_contiguous and not m.classes.flags.writeable
    assert m.cell_size == 10.0 and m.crs == "EPSG:3035" and m.transform[4] == -10.0
    assert m.area_m2 == shape[0] * shape[1] * 100.0 and not m.is_uniform


def test_load_by_name_variants_and_path():
    ref = maps.load_map("35x36_Woods")
    for spec in ("35x36_woods", "35X36_WOODS.TIF", " 35x36_Woods.tif "):
        assert np.array_equal(maps.load_map(spec).classes, ref.classes)
    path = maps.bundled_map_path("35x36_woods")
    assert path.name == "35x36_Woods.tif" and path.is_file()
    by_path = maps.load_map(path)
    assert np.array_equal(by_path.classes, ref.classes) and by_path.source == path
    with pytest.raises(ValueError):  # classes is read-only
        ref.classes[0, 0] = 2


def test_uniform_map():
    for m in (maps.load_map("uniform"), maps.load_map(""), maps.uniform_map()):
        assert m.shape == (50, 50) and m.is_uniform and m.name == "uniform"
        assert maps.class_histogram(m) == {16: 2500} and m.cell_size == 10.0 and m.crs is None
    assert maps.load_map("UNIFORM", rows=7, cols=9).shape == (7, 9)
    with pytest.raises(MapError, match="positive"):
        maps.uniform_map(0, 5)


def test_a_uniform_map_too_big_for_memory_is_refused_before_it_is_allocated(monkeypatch):
    from roshan import memory

    monkeypatch.setattr(memory, "available_memory", lambda: (8 * 2**30, "test"))  # whatever the machine has
    with pytest.raises(memory.MemoryLimitError, match=r"the uniform map of 100,000 x 100,000 cells needs an estimated "
                                               r".*smaller map.uniform_rows / map.uniform_cols"):
        maps.uniform_map(100_000, 100_000)  # 37 GiB of class ids: numpy's MemoryError (a traceback) before


def test_unknown_name_suggests_closest():
    with pytest.raises(MapError) as err:
        maps.load_map("Borkenberg")
    msg = str(err.value)
    assert msg.startswith("Borkenberg:") and "did you mean 'Borkenberge'" in msg and "35x36_Woods" in msg
    with pytest.raises(MapError, match="did you mean '35x36_Woods'"):
        maps.bundled_map_path("35x35_Woods")


# ---------------------------------------------------------------- read_geotiff errors


def test_text_file_is_not_a_raster(tmp_path):
    path = tmp_path / "notes.tif"
    path.write_text("this is not a raster\n")
    with pytest.raises(MapError, match=r"notes\.tif: not a readable raster"):
        maps.read_geotiff(path)
    with pytest.raises(MapError, match="file not found"):
        maps.read_geotiff(tmp_path / "missing.tif")


def test_two_band_raster(tmp_path):
    data = np.stack([np.full((3, 4), 2, np.uint8), np.full((3, 4), 6, np.uint8)])
    path = write_tif(tmp_path / "two.tif", data)
    with pytest.raises(MapError, match=r"two\.tif: the file has 2 bands; choose one with --band N"):
        maps.read_geotiff(path)
    assert maps.class_histogram(maps.load_map(path, band=2)) == {6: 12}
    for band in (0, 3):
        with pytest.raises(MapError, match=f"band {band} out of range"):
            maps.read_geotiff(path, band=band)


def test_rotated_raster(tmp_path):
    path = write_tif(tmp_path / "rot.tif", np.full((3, 3), 2, np.uint8), transform=Affine(10, 2, 0, 2, -10, 0))
    with pytest.raises(MapError, match=r"rot\.tif: rotated or sheared raster.*north-up expected"):
        maps.read_geotiff(path)


def test_non_square_and_south_up(tmp_path):
    path = write_tif(tmp_path / "rect.tif", np.full((3, 3), 2, np.uint8), transform=Affine(10, 0, 0, 0, -20, 0))
    with pytest.raises(MapError, match=r"rect\.tif: non-square cells: 10 wide x 20 high"):
        maps.read_geotiff(path)
    path = write_tif(tmp_path / "south.tif", np.full((3, 3), 2, np.uint8), transform=Affine(10, 0, 0, 0, 10, 0))
    with pytest.raises(MapError, match=r"south\.tif: south-up raster"):
        maps.read_geotiff(path)


def test_geographic_crs_rejected(tmp_path):
    path = write_tif(tmp_path / "geo.tif", np.full((3, 3), 2, np.uint8), Affine(1e-4, 0, 7, 0, -1e-4, 51), "EPSG:4326")
    with pytest.raises(MapError, match="geographic CRS"):
        maps.read_geotiff(path)


@pytest.mark.filterwarnings("ignore::rasterio.errors.NotGeoreferencedWarning")
def test_ungeoreferenced_raster_uses_10_m(tmp_path):
    path = write_tif(tmp_path / "plain.tif", np.full((2, 3), 7, np.uint8), transform=Affine.identity(), crs=None)
    m = maps.read_geotiff(path)
    assert m.cell_size == 10.0 and m.transform is None and m.crs is None and m.shape == (2, 3)


def test_empty_raster(tmp_path):
    try:
        path = write_tif(tmp_path / "empty.tif", np.zeros((0, 4), np.uint8))
    except rasterio.errors.RasterioIOError:
        pass  # GDAL refuses to write 0-sized GeoTIFFs; the in-memory check below still covers the rule
    else:
        with pytest.raises(MapError, match="empty raster"):
            maps.read_geotiff(path)
    with pytest.raises(MapError, match="empty map"):
        maps.LandCoverMap("x", np.zeros((0, 4), np.int32), 10.0, None, None, None)


def test_bad_class_values_listed_with_counts(tmp_path):
    data = np.full((4, 5), 2.0, np.float32)
    data[0, :3] = 0
    data[1, 0] = 100
    data[2, 0] = 12
    path = write_tif(tmp_path / "bad.tif", data)
    with pytest.raises(MapError) as err:
        maps.read_geotiff(path)
    assert str(err.value) == (
        f"{path}: class values outside the CLC+ table: 0 (3 cells), 12 (1 cell), 100 (1 cell); "
        "expected 1-11, 15, 16 (254/255 = outside area/no data)"
    )


def test_non_integral_values(tmp_path):
    data = np.full((3, 3), 2.0, np.float32)
    data[0, 0] = 2.5
    data[1, :2] = 0.25
    path = write_tif(tmp_path / "frac.tif", data)
    with pytest.raises(MapError, match=r"frac\.tif: non-integral values.*0\.25 \(2 cells\), 2\.5 \(1 cell\)"):
        maps.read_geotiff(path)


def test_outside_area_and_nodata_remapped(tmp_path):
    data = np.array([[2, 254, 255], [200, 6, 16]], np.uint8)
    m = maps.read_geotiff(write_tif(tmp_path / "nd.tif", data, nodata=200))
    assert m.classes.tolist() == [[2, 15, 15], [15, 6, 16]]
    data = np.array([[np.nan, 3.0], [-9999.0, 15.0]], np.float32)
    m = maps.read_geotiff(write_tif(tmp_path / "nan.tif", data, nodata=-9999.0))
    assert m.classes.tolist() == [[15, 3], [15, 15]]


# ---------------------------------------------------------------- describe


def test_describe_map():
    text = maps.describe_map(maps.load_map("35x36_Woods"))
    for part in ("35x36_Woods", "35 rows x 36 cols", "350 m", "360 m", "EPSG:3035", "Sealed", "242", "19.21 %"):
        assert part in text
    assert "Ignitable" in text
    text = maps.describe_map(maps.load_map("Borkenberge"))
    assert (
        "4810 m" in text and "7580 m" in text and "Water" in text and "Ignitable:  95.14 %" in text
    )  # water + bare = 17731 cells
    assert "Generic unburned" in maps.describe_map(maps.uniform_map(3, 4))


# ---------------------------------------------------------------- crop_map


@pytest.fixture(scope="module")
def borkenberge():
    with rasterio.open(maps.bundled_map_path("Borkenberge")) as src:
        return src.read(1), src.transform


def test_crop_in_raster_crs(tmp_path, borkenberge, monkeypatch):
    full, transform = borkenberge
    reads = []
    original_read = rasterio.io.DatasetReader.read

    def spy(self, *args, **kwargs):
        reads.append(kwargs.get("window"))
        return original_read(self, *args, **kwargs)

    monkeypatch.setattr(rasterio.io.DatasetReader, "read", spy)
    window = rasterio.windows.Window(200, 100, 80, 50)  # col_off, row_off, width, height
    bounds = window_bounds(window, transform)
    m = maps.crop_map(maps.bundled_map_path("Borkenberge"), bounds, tmp_path / "sub" / "crop.tif")
    assert reads[0] is not None and reads[0].width == 80  # only the window was read from the source
    assert m.shape == (50, 80) and m.name == "crop"
    assert np.array_equal(m.classes, full[100:150, 200:280])
    assert m.transform[2] == pytest.approx(transform.c + 2000.0) and m.transform[5] == pytest.approx(transform.f - 1000)
    with rasterio.open(tmp_path / "sub" / "crop.tif") as out:
        assert out.count == 1 and out.dtypes[0] == "float32" and out.crs.to_string() == "EPSG:3035"
        assert out.compression.value.lower() == "deflate"


def test_crop_with_lonlat_bounds(tmp_path, borkenberge):
    full, transform = borkenberge
    window = rasterio.windows.Window(300, 200, 60, 40)
    lonlat = rasterio.warp.transform_bounds("EPSG:3035", "EPSG:4326", *window_bounds(window, transform))
    m = maps.crop_map(maps.bundled_map_path("Borkenberge"), lonlat, tmp_path / "ll.tif", bounds_crs="EPSG:4326")
    col0 = round((m.transform[2] - transform.c) / 10.0)
    row0 = round((transform.f - m.transform[5]) / 10.0)
    # The lon/lat box is slightly larger than the original window (grid convergence); it must contain it.
    assert 295 <= col0 <= 300 and 195 <= row0 <= 200
    assert 360 <= col0 + m.cols <= 365 and 240 <= row0 + m.rows <= 245
    assert np.array_equal(m.classes, full[row0 : row0 + m.rows, col0 : col0 + m.cols])


def test_crop_outside_or_invalid(tmp_path, borkenberge):
    _, transform = borkenberge
    src = maps.bundled_map_path("Borkenberge")
    far = (transform.c - 5000, transform.f + 1000, transform.c - 4000, transform.f + 2000)
    with pytest.raises(MapError, match="outside the raster"):
        maps.crop_map(src, far, tmp_path / "far.tif")
    assert not (tmp_path / "far.tif").exists()
    with pytest.raises(MapError, match="invalid bounds"):
        maps.crop_map(src, (far[2], far[1], far[0], far[3]), tmp_path / "swap.tif")


def test_crop_partial_overlap_warns(tmp_path, borkenberge):
    full, transform = borkenberge
    bounds = (transform.c - 100, transform.f - 200, transform.c + 300, transform.f + 50)
    with pytest.warns(UserWarning, match="cropping to the overlap"):
        m = maps.crop_map(maps.bundled_map_path("Borkenberge"), bounds, tmp_path / "corner.tif")
    assert np.array_equal(m.classes, full[:20, :30])
