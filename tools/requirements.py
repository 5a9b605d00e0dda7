"""Print requirements from pyproject.toml, one per line (for pip install -r), so the Makefile
installs what pyproject.toml lists instead of a copy of it.

usage: python tools/requirements.py GROUP...
GROUP: "build" (build-system.requires), "project" (project.dependencies), or the name of an
optional-dependency extra ("test", "bench", ...).
"""

import pathlib
import sys

try:
    import tomllib
except ImportError:  # Python 3.10
    import tomli as tomllib


def main(groups: list[str]) -> int:
    if not groups:
        print(__doc__.strip(), file=sys.stderr)
        return 2
    meta = tomllib.loads(
        (pathlib.Path(__file__).resolve().parents[1] / "pyproject.toml").read_text()
    )
    extras = meta["project"].get("optional-dependencies", {})
    for group in groups:
        if group == "build":
            reqs = meta["build-system"]["requires"]
        elif group == "project":
            reqs = meta["project"].get("dependencies", [])
        elif group in extras:
            reqs = extras[group]
        else:
            known = ", ".join(["build", "project", *extras])
            print(
                f"requirements.py: unknown group {group!r}; expected one of {known}",
                file=sys.stderr,
            )
            return 2
        print("\n".join(reqs))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
