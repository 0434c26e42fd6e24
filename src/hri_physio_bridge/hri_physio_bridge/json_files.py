"""Strict JSON for the files and events a session leaves behind."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path
from typing import Any


def json_safe(value: Any) -> Any:
    """``value`` with NaN/inf as null (recursively) and paths as text: JSON has neither."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [json_safe(v) for v in value]
    if isinstance(value, Path):
        return str(value)
    return value


def strict_json(value: Any, **dumps_options: Any) -> str:
    """``value`` as strict JSON text (see :func:`json_safe`)."""
    return json.dumps(json_safe(value), allow_nan=False, **dumps_options)


def write_text_atomic(path: Path, text: str) -> Path:
    """Write next to ``path`` and rename over it: a reader never sees half a file."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return path
