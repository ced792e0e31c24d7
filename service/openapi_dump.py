"""Write the app's OpenAPI document: ``python -m service.openapi_dump [path]`` (default openapi/openapi.json)."""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any


def document() -> dict[str, Any]:
    from service.app import create_app

    spec: dict[str, Any] = create_app().openapi()
    return spec


def text() -> str:
    return json.dumps(document(), indent=2, sort_keys=True) + "\n"


def main() -> None:
    path = Path(sys.argv[1] if len(sys.argv) > 1 else "openapi/openapi.json")
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text())
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
