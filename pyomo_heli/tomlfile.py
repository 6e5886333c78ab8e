"""Reading a TOML config with an error that names the file (shared by all configs)."""
from __future__ import annotations

import tomllib
from pathlib import Path


def read_toml(path: str | Path, error: type[Exception]) -> dict:
    """Parse ``path``; a missing file or bad TOML raises ``error`` naming the file."""
    path = Path(path)
    if path.is_dir():
        raise error(f"{path}: is a directory, expected a file (the config .toml)")
    if not path.is_file():
        raise error(f"{path}: config file not found")
    try:
        text = path.read_text(encoding="utf-8")
        if text.startswith("\ufeff"):  # tomllib would say only "Invalid statement (at line 1, column 1)"
            raise error(f"{path}: starts with a byte-order mark (BOM, bytes EF BB BF), which TOML does not allow; "
                        f"save the file as UTF-8 without BOM")
        return tomllib.loads(text)
    except UnicodeDecodeError as exc:
        raise error(f"{path}: not a UTF-8 text file ({exc.reason} at byte {exc.start})") from None
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{path}: not valid TOML ({exc})") from None
