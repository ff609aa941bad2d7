"""Where the code and the package live (`[project.urls]` of the installed distribution), and the Hub repos the shipped
artifacts go to. While the URLs are placeholders under `example.invalid` (a domain reserved never to resolve),
`require_public_urls()` refuses `blindgrasp-publish` and `code_line()` never writes one into a card.
"""

from __future__ import annotations

import importlib.metadata
import re

# The shape of a Hub repo id, checked before anything is written or uploaded.
REPO_ID_PATTERN = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*/[A-Za-z0-9][A-Za-z0-9_.-]*$")
DIST = "lerobot_policy_blindgrasp"  # LeRobot's plugin discovery imports the module named like the distribution
PLACEHOLDER_HOST = "example.invalid"
# The Hub repo names of the shipped artifacts, under `blindgrasp-publish --namespace=`: folder under models/ (or
# "demos" for the dataset) -> (repo type, repo name).
HUB_REPOS = {
    "teacher_cpu_bc": ("model", "blindgrasp-teacher-cpu-bc"),
    "teacher_cpu_bc_calib": ("model", "blindgrasp-teacher-cpu-bc-calib"),
    "student_cpu": ("model", "blindgrasp-student-cpu"),
    "demos": ("dataset", "blindgrasp-demos-sim"),
}


class PlaceholderURLError(RuntimeError):
    """A card would go out naming a code location that does not exist."""


def urls() -> dict[str, str]:
    """`[project.urls]` of the installed distribution: label -> URL."""
    try:
        lines = importlib.metadata.metadata(DIST).get_all("Project-URL") or []
    except importlib.metadata.PackageNotFoundError:
        return {}
    return dict(tuple(s.strip() for s in line.split(",", 1)) for line in lines if "," in line)


def source_url() -> str:
    """Where the code lives (`[project.urls] Source`); '' if the installed metadata names none."""
    return urls().get("Source", "")


def is_placeholder(url: str) -> bool:
    return not url or PLACEHOLDER_HOST in url


def require_public_urls() -> dict[str, str]:
    """The project URLs, or PlaceholderURLError while they are missing or still placeholders."""
    found = urls()
    bad = [label for label in ("Homepage", "Source") if is_placeholder(found.get(label, ""))]
    if bad:
        raise PlaceholderURLError(
            f"[project.urls] {', '.join(bad)} in pyproject.toml: placeholder or missing "
            f"({found.get(bad[0]) or 'nothing'}); set the project's real public address there and reinstall "
            "(pip install -e .) before pushing a card that names it"
        )
    return found


def code_line() -> str:
    """One markdown line for a card: where the code, its issues and its guides are. A placeholder is never written
    into a card (a user's own dataset or student card included): the line then says the location is not set."""
    src = source_url()
    if is_placeholder(src):
        return (f"Code: the `{DIST}` package (importable as `lerobot_blindgrasp`); its public source location is "
                "not set yet.")  # fmt: skip
    return f"Code, guides and issues: {src} (package `{DIST}`, importable as `lerobot_blindgrasp`)."


def install_line() -> str:
    """The shell line that installs the plugin, for a card: from the public Source with pip's `git+` form, or, while
    that is a placeholder, the wheel built from the code (it is not on the package index)."""
    from lerobot_blindgrasp import __version__

    src = source_url()
    if is_placeholder(src):
        return (f"pip install dist/{DIST}-{__version__}-py3-none-any.whl   # built from the code by python -m build; "
                "not on the package index")  # fmt: skip
    return f'pip install "{DIST} @ git+{src}"'
