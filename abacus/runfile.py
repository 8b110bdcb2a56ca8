"""The run file: a scene file whose ``processing:`` block the application parses.

A scene file is the forward model's (``acoustics.load_scene``) and, in its ``processing:``
block, processing's settings (:class:`processing.settings.ProcessingSettings`). The forward
model keeps that block as written and never reads it; this module validates it — with the
file, line and key of every problem, like the rest of the scene — resolves it (every default
filled in, so that a run's recorded scene says what processing used), and checks it against the
scene (a threshold derived from noise in a scene without noise).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from acoustics.scene.errors import SceneError, raise_problems, warn_problems
from processing.base.config import ConfigError, ConfigModel, validate_file
from processing.settings import ProcessingSettings

__all__ = ["load_run", "settings_of", "settings_problems", "record_problems", "record_window_m",
           "resolve_processing", "json_schema", "json_schema_text"]


class _RunProcessing(ConfigModel):
    """The run file seen from processing: its ``processing:`` block (other keys are the scene's)."""

    model_config = {**ConfigModel.model_config, "extra": "ignore"}
    processing: ProcessingSettings = ProcessingSettings()


def _validated(block, *, file, marks=None) -> ProcessingSettings:
    try:
        return validate_file(_RunProcessing, {"processing": block if block is not None else {}},
                             file=file, marks=marks).processing
    except ConfigError as exc:
        raise SceneError(str(exc), exc.problems) from None


@lru_cache(maxsize=64)
def _settings_of_text(text: str, file: str) -> ProcessingSettings:
    from processing.base.config import parse_yaml
    data, marks = parse_yaml(text, source=file)
    return _validated((data or {}).get("processing"), file=file, marks=marks)


def settings_of(scene) -> ProcessingSettings:
    """The processing settings of a scene's ``processing:`` block, validated (defaults filled).

    Raises
    ------
    SceneError
        A key or value the settings refuse, with the key path.
    """
    import json
    file = str(scene.source_path or scene.name)
    # keyed on the block's text: scenes are frozen, and a sweep's variants differ in it
    return _settings_of_text(json.dumps({"processing": scene.processing}, sort_keys=True), file)


def resolve_processing(scene):
    """The scene with its ``processing:`` block validated and every default filled in (what a
    run records in /Provenance and ``scene.resolved.yaml``)."""
    settings = settings_of(scene)
    return scene.model_copy(update={"processing": settings.model_dump(mode="json", by_alias=True)})


def record_window_m(scene) -> tuple[float, float]:
    """The ranges (m) a scene's record spans, c·t/2 from ``sampling.time_offset_s`` to the end
    of its last sample (``time_offset_s + samples / rate_hz``): where an image can be formed."""
    c, s = scene.medium.sound_speed_m_s, scene.sampling
    return c * s.time_offset_s / 2, c * (s.time_offset_s + s.samples / s.rate_hz) / 2


def _record_how(scene) -> str:
    s = scene.sampling
    return (f"c·t/2 for t from sampling.time_offset_s = {s.time_offset_s:g} s over sampling.samples "
            f"= {s.samples} at sampling.rate_hz = {s.rate_hz:g} Hz")


def record_problems(scene, settings: ProcessingSettings) -> list[tuple[str, str]]:
    """Settings that the scene's record cannot serve at all — processing would stop on them:
    (message, key path) pairs that make the run file an error (``abacus scene check`` reports
    them, not ``abacus run`` halfway)."""
    out = []
    near, far = record_window_m(scene)
    image = settings.image.range_m
    if image is not None and (image[0] >= far or image[1] <= near):
        need = int(np.ceil((2 * image[0] / scene.medium.sound_speed_m_s
                            - scene.sampling.time_offset_s) * scene.sampling.rate_hz)) + 1
        out.append((f"the image range {image[0]:g}–{image[1]:g} m lies outside the record, "
                    f"{near:.4g}–{far:.4g} m ({_record_how(scene)}): give an image range that "
                    f"overlaps the record, or record farther (sampling.samples of at least {need})"
                    if image[0] >= far else
                    f"the image range {image[0]:g}–{image[1]:g} m lies outside the record, "
                    f"{near:.4g}–{far:.4g} m ({_record_how(scene)}): give an image range that "
                    f"overlaps the record, or start recording earlier (sampling.time_offset_s)",
                    "processing.image.range_m"))
        return out
    lo, hi = (near, far) if image is None else (max(near, image[0]), min(far, image[1]))
    noise = settings.detect.noise
    if settings.detect.needs_noise and noise.source == "region" and noise.range_m is not None:
        a, b = noise.range_m
        if a >= hi or b <= lo:
            out.append((f"the noise region {a:g}–{b:g} m holds no image cell: the image spans "
                        f"{lo:.4g}–{hi:.4g} m (processing.image.range_m within the record); give a "
                        f"region inside it", "processing.detect.noise.range_m"))
    return out


def settings_problems(scene, settings: ProcessingSettings) -> list[tuple[str, str]]:
    """Settings that are legal but defeat themselves on this scene: (message, key path) pairs."""
    out = []
    near, far = record_window_m(scene)
    image = settings.image.range_m
    if image is not None and image[0] < far and image[1] > near and (image[0] < near
                                                                     or image[1] > far):
        out.append((f"the image range {image[0]:g}–{image[1]:g} m reaches beyond the record, "
                    f"{near:.4g}–{far:.4g} m ({_record_how(scene)}): the image stops at the "
                    f"record's ends", "processing.image.range_m"))
    count = settings.count.range_m
    lo, hi = (near, far) if image is None else (max(near, image[0]), min(far, image[1]))
    if count is not None and (count[0] >= hi or count[1] <= lo):
        out.append((f"the counting range {count[0]:g}–{count[1]:g} m holds no image cell (the "
                    f"image spans {lo:.4g}–{hi:.4g} m): nothing can be counted there",
                    "processing.count.range_m"))
    st = settings.detect
    background = scene.noise.enabled or (scene.effects.reverberation.enabled and scene.boundaries)
    if st.needs_noise and st.noise.source in ("image", "region") and not background:
        # the Rayleigh fit then takes the targets' sidelobes and the numerical floor for noise:
        # its threshold sits below the sidelobes and counts them (point_target: 53 for 1)
        out.append((f"the images hold no noise (noise.enabled is false, and no reverberation), "
                    f"yet the detection threshold is derived from their noise (method "
                    f"'{st.method}'): it would be fitted to the targets' own sidelobes and count "
                    f"them; use method 'fraction_of_peak' (with fraction) or 'fixed' (with value "
                    f"in counts), or enable noise", "processing.detect.method"))
    return out


def load_run(path, *, check: bool = True):
    """Read a run file (a scene file, or a built-in scene's name): the scene with its processing
    block validated and resolved.

    Parameters
    ----------
    path : str or Path
    check : bool
        Warn (:class:`~acoustics.scene.SceneWarning`) of legal but surprising physics and
        settings, each with file, line and key.

    Returns
    -------
    Scene
        ``scene.processing`` holds every processing setting (:func:`settings_of` gives them
        as :class:`~processing.settings.ProcessingSettings`).

    Raises
    ------
    SceneError
        As :func:`acoustics.load_scene`, and for the processing block.
    """
    from acoustics.scene.builtin import resolve_scene_argument
    from acoustics.scene.load import load_scene
    from processing.base.config import read_yaml
    path = resolve_scene_argument(path)
    scene = load_scene(path, check=check)
    try:
        _, marks = read_yaml(path)
    except ConfigError:
        marks = {}
    settings = _validated(scene.processing, file=path, marks=marks)
    raise_problems(record_problems(scene, settings), file=path, marks=marks)
    if check:
        warn_problems(settings_problems(scene, settings), file=path, marks=marks)
    return scene.model_copy(update={"processing": settings.model_dump(mode="json", by_alias=True)})


def json_schema() -> dict:
    """JSON Schema of a run file: the scene's (:func:`acoustics.scene.json_schema`) with the
    ``processing`` block described by :class:`~processing.settings.ProcessingSettings`."""
    from processing.base.config import FIELD_DOCS
    if not FIELD_DOCS:   # the keys' descriptions are their docstrings, read by a process that asks
        import json
        import os
        import subprocess
        import sys
        done = subprocess.run([sys.executable, "-c", "import json, abacus.runfile as r; "
                               "print(json.dumps(r.json_schema()))"],
                              env={**os.environ, "ABACUS_FIELD_DOCS": "1"}, capture_output=True,
                              text=True, check=True)
        return json.loads(done.stdout)
    from acoustics.scene import json_schema as scene_schema
    schema = scene_schema()
    proc = ProcessingSettings.model_json_schema(by_alias=True, mode="validation")
    defs = schema.setdefault("$defs", {})
    clash = set(defs) & set(proc.get("$defs", {}))
    if clash:   # pragma: no cover - a renamed model would make two schemas share a name
        raise RuntimeError(f"scene and processing schemas both define {sorted(clash)}")
    defs.update(proc.pop("$defs", {}))
    defs["ProcessingSettings"] = proc
    schema["properties"]["processing"] = {
        "$ref": "#/$defs/ProcessingSettings",
        "default": ProcessingSettings().model_dump(mode="json", by_alias=True),
        "description": ("processing settings (imaging, detection, counting, tracking), read by the "
                        "application and processing; the forward model keeps them as written")}
    return schema


def json_schema_text() -> str:
    """:func:`json_schema` as indented JSON text."""
    import json
    return json.dumps(json_schema(), indent=2, sort_keys=False) + "\n"
