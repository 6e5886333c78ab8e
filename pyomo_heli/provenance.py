"""What a results folder was made from, and the check that a config agrees with it.

An identification records in ``chosen.json`` (``info``), besides the config's name:

- ``config_sha256`` and ``config_text``: the config file by content (a relative name resolves to
  another file in another checkout);
- ``maneuvers``: the maneuvers fitted (already recorded before these records existed);
- ``dataset_sha256``: SHA-256 over the dataset folder's files (relative names and contents), so the
  same data in another place agrees and an edited or other flight test does not;
- ``model`` and ``model_fingerprint``: the fixed model parameter values [SI], the extensions (by the
  hash of their source, :func:`pyomo_heli.physics.extensions.extension_forms`) and the settings that decide
  what the model is compared with (outputs, input errors, resampling, crop, input reference), and
  the SHA-256 of that record;
- ``noise_model``: the noise sigmas, the AR orders of the input errors and output noise, the input reference
  error and the collocation points per interval (:func:`noise_record`), which the likelihood and the standard
  errors rest on (outside the fingerprint, so that folders made before it still match);

and ``parameters`` (the free parameters) at the top level of ``chosen.json``.

Every command that reads a results folder with a config (``diagnose``, ``uncertainty``,
``report-linear``, a resumed ``close-loop``) calls :func:`check_results_match`: a mismatch of the
free parameters, fitted maneuvers, dataset content, model or noise model is refused with one line naming both
sides (:class:`ResultsMismatchError`); a record the folder lacks (folders written before it existed,
e.g. the committed ones under docs/results) is not checked and a one-line warning says so; a config
whose text differs from the recorded one while all of that agrees gets a one-line note.
"""
from __future__ import annotations

import functools
import hashlib
import json
import sys
from pathlib import Path


class ResultsMismatchError(ValueError):
    """A results folder and the config given with it do not belong together (one line naming both)."""


def _canonical(obj) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=str)


def _tree_sha256(root: Path, pattern: str = "*") -> str:
    """SHA-256 over the files of ``root`` matching ``pattern`` (recursively): each path relative to it and content."""
    h = hashlib.sha256()
    for f in sorted(p for p in root.rglob(pattern) if p.is_file()):
        h.update(f.relative_to(root).as_posix().encode())
        h.update(hashlib.sha256(f.read_bytes()).digest())
    return h.hexdigest()


def dataset_sha256(dataset: str | Path) -> str:
    """SHA-256 over every file of a dataset folder: its path relative to the folder and its content."""
    return _tree_sha256(Path(dataset))


@functools.lru_cache(maxsize=1)
def source_sha256() -> str:
    """SHA-256 over this package's Python sources: a stored intermediate result that is reused only by the code
    that made it (the closed loop's structure steps) carries it."""
    return _tree_sha256(Path(__file__).resolve().parent, "*.py")


def model_record(cfg) -> dict:
    """The model a config fits and what it is compared with (JSON; floats round-trip exactly)."""
    from .physics.extensions import extension_forms

    free = {f.name for f in cfg.free}
    nlp = cfg.nlp
    return {"fixed_parameters": {n: float(v) for n, v in cfg.model.parameters.to_dict().items() if n not in free},
            "extensions": extension_forms(cfg.model.extensions),
            "settings": {"time_outputs": list(nlp.time_outputs), "trim_outputs": list(nlp.trim_outputs),
                         "input_errors": list(nlp.input_errors), "covariance": nlp.covariance,
                         "resample_hz": cfg.resample_hz, "max_duration_s": cfg.max_duration,
                         "input_reference_s": cfg.input_reference_s,
                         "resample_inputs": cfg.resample_inputs if cfg.resample_hz else None}}


def model_fingerprint(record: dict) -> str:
    return hashlib.sha256(_canonical(record).encode()).hexdigest()


def config_sha256(path: str | Path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def fitted_maneuvers(cfg, ft=None) -> list[str]:
    """The maneuvers an identification of ``cfg`` fits (its ``[data] maneuvers`` on its dataset)."""
    if not isinstance(cfg.maneuvers, str):
        return list(cfg.maneuvers)
    if ft is None:
        from .dataset import load_flight_test

        ft = load_flight_test(cfg.dataset)
    return [n for n, mv in ft.maneuvers.items() if mv.role == cfg.maneuvers]


def noise_record(cfg) -> dict:
    """The noise model and discretisation a fit's likelihood and standard errors rest on (JSON): the noise sigmas
    (SI; None: from the records' lead-in), the AR orders of the input errors and the output noise, the records'
    input reference error, the collocation points per interval. Kept beside the model record (not in its fingerprint,
    so that results made before it still match)."""
    nlp = cfg.nlp
    sigma = None if nlp.noise_sigma is None else {k: float(v) for k, v in sorted(nlp.noise_sigma.items())}
    return {"noise_sigma": sigma, "input_error_ar": int(nlp.input_error_ar),
            "output_error_ar": int(nlp.output_error_ar), "input_reference_error": bool(nlp.input_reference_error),
            "ncp": int(nlp.ncp)}


def provenance_info(cfg) -> dict:
    """The records an identification adds to ``chosen.json``'s ``info`` (see the module docstring)."""
    rec = model_record(cfg)
    out = {"dataset_sha256": dataset_sha256(cfg.dataset), "model": rec, "model_fingerprint": model_fingerprint(rec),
           "noise_model": noise_record(cfg)}
    try:
        raw = Path(cfg.path).read_bytes()
    except OSError:  # a config object not read from a file (tests): nothing to record by content
        return out
    out["config_sha256"] = hashlib.sha256(raw).hexdigest()
    out["config_text"] = raw.decode("utf-8", errors="replace")
    return out


def _warn(msg: str) -> None:
    print(f"warning: {msg}", file=sys.stderr)


def _short(h) -> str:
    return str(h)[:12]


def _model_difference(have: dict, want: dict) -> str:
    """What differs between two model records, briefly (for the one-line refusal)."""
    parts = []
    hp, wp = have.get("fixed_parameters", {}), want.get("fixed_parameters", {})
    diff = sorted(n for n in set(hp) | set(wp) if hp.get(n) != wp.get(n))
    if diff:
        parts.append("fixed parameter(s) " + ", ".join(f"{n} (results {hp.get(n)!r}, config {wp.get(n)!r})"
                                                       for n in diff[:3]) + (", ..." if len(diff) > 3 else ""))
    if have.get("extensions") != want.get("extensions"):
        parts.append(f"extensions (results {have.get('extensions')}, config {want.get('extensions')})")
    hs, ws = have.get("settings", {}), want.get("settings", {})
    diff = sorted(k for k in set(hs) | set(ws) if hs.get(k) != ws.get(k))
    if diff:
        parts.append("setting(s) " + ", ".join(f"{k} (results {hs.get(k)!r}, config {ws.get(k)!r})" for k in diff))
    return "; ".join(parts) or "the model record"


def check_results_match(cfg, result, results_dir, ft=None, warn=_warn) -> None:
    """Refuse (ResultsMismatchError, one line) a config that does not describe the results in ``results_dir``.

    Compared: the free parameters, the fitted maneuvers, the dataset's content and the model (see the module
    docstring). ``cfg`` is the config as the identification used it (for an iteration of close-loop, after
    :func:`pyomo_heli.config.config_of_result`). Records the folder lacks are not checked: ``warn`` says
    so in one line.
    """
    where = f"results folder {results_dir} and config {cfg.path}"
    fix = "give the config the results came from (recorded in chosen.json info.config_text)"
    have, want = list(result.parameters), [f.name for f in cfg.free]
    missing = [n for n in want if n not in have]
    extra = [n for n in have if n not in want]
    if missing or extra:
        parts = []
        if missing:
            parts.append(f"config {cfg.path} frees {', '.join(missing)}, which results folder {results_dir} lacks")
        if extra:
            parts.append(f"results folder {results_dir} holds {', '.join(extra)}, "
                         f"which config {cfg.path} does not free")
        raise ResultsMismatchError("; ".join(parts) + f" (results: {', '.join(have) or 'none'}; "
                                   f"config: {', '.join(want) or 'none'}); give the config the results came from")
    info = result.info
    unchecked = []
    fitted = info.get("maneuvers")
    if isinstance(fitted, list):
        now = fitted_maneuvers(cfg, ft)
        if sorted(fitted) != sorted(now):
            raise ResultsMismatchError(f"{where} disagree: the results fitted maneuvers {', '.join(fitted)}, the "
                                       f"config selects {', '.join(now) or 'none'}; {fix}")
    else:
        unchecked.append("fitted maneuvers")
    recorded = info.get("dataset_sha256")
    if recorded:
        now = dataset_sha256(cfg.dataset)
        if now != recorded:
            raise ResultsMismatchError(f"{where} disagree: the results were fitted to a dataset of content "
                                       f"{_short(recorded)} (info.dataset {info.get('dataset')}), the config's "
                                       f"dataset {cfg.dataset} has content {_short(now)}: other or edited data; "
                                       f"{fix}")
    else:
        unchecked.append("dataset content")
    recorded = info.get("model_fingerprint")
    if recorded:
        rec = model_record(cfg)
        if model_fingerprint(rec) != recorded:
            what = _model_difference(info.get("model") or {}, rec)
            raise ResultsMismatchError(f"{where} disagree: the model differs: {what}; {fix}")
    else:
        unchecked.append("model")
    recorded = info.get("noise_model")
    if recorded is not None:  # results made before this record: the model check above is all there is
        now = json.loads(json.dumps(noise_record(cfg)))
        diff = sorted(k for k in set(recorded) | set(now) if recorded.get(k) != now.get(k))
        if diff:
            raise ResultsMismatchError(f"{where} disagree: the noise model differs: " + ", ".join(
                f"{k} (results {recorded.get(k)!r}, config {now.get(k)!r})" for k in diff) + f"; {fix}")
    if unchecked:
        warn(f"{results_dir}/chosen.json records no {', no '.join(unchecked)} (written before these records "
             f"existed): not checked against config {cfg.path}")
    elif info.get("config_sha256") and Path(cfg.path).is_file() and config_sha256(cfg.path) != info["config_sha256"]:
        warn(f"config {cfg.path} is not the file {results_dir} was made with (its text is in chosen.json "
             f"info.config_text); the free parameters, fitted maneuvers, dataset and model agree")
