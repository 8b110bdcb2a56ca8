"""Training data: randomised scenes, their images and label cubes, in files NumPy reads.

``abacus dataset -o OUT --scenes N --seed S`` (docs/training.md) draws N scenes from one seeded
distribution — a horizontal ABACUS 3 m under the sea looking at a fish school, the school's
size, packing, range and depth, the sea state (flat, a swell or a wind sea) and the floor's
depth drawn for each — simulates each with its per-arrival ground truth, images it and labels
every image cell (processing/imaging/labels.py). Scene i depends only on (S, i): any subset of
a run is reproducible alone.

Layout of OUT::

    sample_00000.npz    image_db (pings, range, beams) float32: 20 log10 |I| (ADC counts),
                        label_class (int8), label_id (int64), label_fraction (float32),
                        range_m (range,), beam_angle_rad (beams,)
    sample_00000.yaml   the scene drawn (abacus simulate runs it again)
    index.csv           one row per sample: the drawn parameters

Every sample has the same shape (the image's range limits and beams are fixed).
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

__all__ = ["SEA_STATES", "FLOORS", "draw_scene", "write_sample", "make_dataset"]

#: the sea states drawn, with equal probability
SEA_STATES = ("flat", "swell", "wind_sea")
#: floor materials drawn, with equal probability: (density kg/m³, sound speed m/s) of a fluid
#: half-space, c = 1500 m/s x the ratio of Jensen et al., Computational Ocean Acoustics (2011), Table 1.3
FLOORS = {"silt": (1700.0, 1575.0), "sand": (1900.0, 1650.0), "gravel": (2000.0, 1800.0),
          "limestone": (2400.0, 3000.0)}
#: the image every sample is cut to (m)
IMAGE_RANGE_M = (8.0, 36.0)


def draw_scene(seed: int, index: int) -> tuple[str, dict]:
    """Scene ``index`` of the distribution seeded by ``seed``: (scene YAML text, its drawn
    parameters)."""
    rng = np.random.default_rng([int(seed), int(index)])
    count = int(rng.integers(5, 81))
    nn = float(rng.uniform(0.3, 1.2))
    rng_m = float(rng.uniform(14.0, 28.0))
    az = float(rng.uniform(-0.12, 0.12))
    # the transmitter's beam is 0.86° thick in elevation: a school it sees straddles its depth
    depth = 3.0 + float(rng.uniform(-0.6, 0.6))
    axes = (float(rng.uniform(1.5, 4.0)), float(rng.uniform(1.0, 3.0)), float(rng.uniform(0.4, 1.5)))
    heading = float(rng.uniform(0.0, 360.0))
    # hard spheres of diameter nn may fill at most 25 % of the school (the drawing's limit): 20 %
    volume = 4.0 / 3.0 * np.pi * axes[0] * axes[1] * axes[2]
    count = max(1, min(count, int(0.2 * volume / (np.pi / 6 * nn ** 3))))
    sea = SEA_STATES[int(rng.integers(len(SEA_STATES)))]
    floor = float(rng.uniform(12.0, 30.0))
    material = list(FLOORS)[int(rng.integers(len(FLOORS)))]
    rho_f, c_f = FLOORS[material]
    x, y = rng_m * np.cos(az), rng_m * np.sin(az)
    if sea == "flat":
        mesh = "{shape: plane, center_m: [22.0, 0.0, 0.0], normal: [0.0, 0.0, 1.0], size_m: [60.0, 30.0]}"
        extra = {}
    elif sea == "swell":
        amp, wl = float(rng.uniform(0.1, 0.5)), float(rng.uniform(15.0, 40.0))
        mesh = ("{shape: swell, center_m: [22.0, 0.0], size_m: [40.0, 16.0], resolution_m: 0.5, "
                f"waves: [{{amplitude_m: {amp:.3f}, wavelength_m: {wl:.2f}, direction_deg: "
                f"{float(rng.uniform(0, 360)):.1f}}}]}}")
        extra = {"swell_amplitude_m": amp, "swell_wavelength_m": wl}
    else:
        wind = float(rng.uniform(4.0, 12.0))
        mesh = ("{shape: wind_sea, wind_speed_m_s: " f"{wind:.2f}" ", fetch_km: 20.0, "
                "center_m: [22.0, 0.0], size_m: [40.0, 16.0], resolution_m: 0.5}")
        extra = {"wind_speed_m_s": wind}
    text = f"""schema_version: 1
name: training-{seed}-{index}
description: a drawn scene of `abacus dataset` (seed {seed}, sample {index})
seed: {int(rng.integers(0, 2**31))}
sonar:
  pose: {{position_m: [0.0, 0.0, 3.0], boresight: [1.0, 0.0, 0.0], receiver_axis: [0.0, 1.0, 0.0]}}
medium: {{sound_speed_m_s: 1500.0}}
noise: {{enabled: true}}
targets:
  populations:
    - kind: school
      label: school
      center_m: [{x:.3f}, {y:.3f}, {depth:.3f}]
      semi_axes_m: [{axes[0]:.3f}, {axes[1]:.3f}, {axes[2]:.3f}]
      heading_deg: {heading:.1f}
      count: {count}
      nearest_neighbour_m: {nn:.3f}
boundaries:
  - name: sea surface
    role: surface
    mesh: {mesh}
  - name: sea floor
    role: floor
    mesh: {{shape: plane, center_m: [22.0, 0.0, {floor:.3f}], normal: [0.0, 0.0, -1.0], size_m: [60.0, 30.0]}}
    reflection: {{model: rayleigh, density_kg_m3: {rho_f}, sound_speed_m_s: {c_f}}}
    scattering: null
effects: {{max_bounces: 1, arrivals: {{enabled: true, floor_db: -60.0}}}}
processing:
  image: {{range_m: [{IMAGE_RANGE_M[0]}, {IMAGE_RANGE_M[1]}]}}
"""
    params = {"sample": index, "school_count": count, "school_density_per_m3": count / volume,
              "nearest_neighbour_m": nn,
              "school_range_m": rng_m, "school_azimuth_rad": az, "school_depth_m": depth,
              "sea": sea, "floor_depth_m": floor, "floor": material, **extra}
    return text, params


def write_sample(tree, path: Path) -> None:
    """The image (subarray A) and label cube of a simulated dataset, imaged here, as ``path``
    (.npz)."""
    import processing
    out = processing.image(tree, labels=True)
    im = processing.images_of(out)
    from processing.base.contract import LABELS_GROUP
    from processing.base.dataset import group_of
    lab = group_of(out, LABELS_GROUP)
    mag = np.abs(im.image[:, 0])
    with np.errstate(divide="ignore"):
        image_db = 20 * np.log10(np.maximum(mag, 1e-12)).astype(np.float32)
    np.savez_compressed(path, image_db=image_db,
                        label_class=lab["label_class"].values[:, 0],
                        label_id=lab["label_id"].values[:, 0],
                        label_fraction=lab["label_fraction"].values[:, 0],
                        range_m=im.range_m, beam_angle_rad=im.beam_angle_rad)


def make_dataset(out, n_scenes: int, seed: int, *, pings: int = 1, progress=None) -> Path:
    """Draw, simulate, image and label ``n_scenes`` scenes into the folder ``out``.

    Parameters
    ----------
    out : path
        A new or empty folder.
    n_scenes : int
    seed : int
    pings : int
        Pings per scene.
    progress : callable(done, total), optional

    Returns
    -------
    Path
        The folder.
    """
    import acoustics
    from acoustics.scene.load import scene_from_text
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    rows = []
    for i in range(int(n_scenes)):
        text, params = draw_scene(seed, i)
        (out / f"sample_{i:05d}.yaml").write_text(text)
        tree = acoustics.simulate(scene_from_text(text, name=f"sample_{i:05d}.yaml"), pings=pings)
        write_sample(tree, out / f"sample_{i:05d}.npz")
        rows.append(params)
        if progress is not None:
            progress(i + 1, int(n_scenes))
    keys = list(dict.fromkeys(k for r in rows for k in r))
    with open(out / "index.csv", "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=keys)
        w.writeheader()
        w.writerows(rows)
    return out
