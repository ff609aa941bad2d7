"""Relative markdown links made absolute, for text read away from the repository: the README as the package index's
project page (setup.py's long description) and the shipped models' cards on the Hub. A file's page is under the
`[project.urls]` `Changelog` URL's folder (else `Source` + `/blob/main/`), an image's under `/raw/`. Standard library
only: setup.py loads this file by path at build time, before any of the package's dependencies exist.
"""

from __future__ import annotations

import posixpath
import re

# [text](target) and ![alt](target); the target has no spaces (as the link checker in tests/repo/test_repository.py).
LINK = re.compile(r"(!?)\[([^\]]*)\]\(([^)\s]+)\)")
_ABSOLUTE = re.compile(r"^([a-z][a-z0-9+.-]*:|#|/)", re.IGNORECASE)
CHANGELOG = "CHANGELOG.md"


def file_base(urls: dict[str, str]) -> str:
    """The URL a repository path is appended to, to reach that file's page (ends with '/')."""
    changelog = urls.get("Changelog", "")
    if changelog.endswith("/" + CHANGELOG):
        return changelog[: -len(CHANGELOG)]
    source = urls.get("Source", "").rstrip("/")
    if not source:
        raise ValueError("[project.urls] names neither a Changelog file URL nor a Source; no link can be made")
    return f"{source}/blob/main/"


def raw_base(urls: dict[str, str]) -> str:
    """The URL a repository path is appended to, to reach that file's bytes (for images)."""
    return file_base(urls).replace("/blob/", "/raw/", 1)


def repo_path(target: str, doc: str) -> tuple[str, str]:
    """(path in the repository, '#fragment' or '') of a relative link `target` written in the file `doc`."""
    path, hashmark, fragment = target.partition("#")
    joined = posixpath.normpath(posixpath.join(posixpath.dirname(doc), path))
    if joined == ".." or joined.startswith("../"):
        raise ValueError(f"{doc}: link {target!r} leaves the repository")
    return joined, hashmark + fragment


def is_relative(target: str) -> bool:
    return not _ABSOLUTE.match(target)


def _rewrite(text: str, doc: str, keep_under: str | None, make) -> str:
    """Each relative link of `text` (at repository path `doc`) that leaves `keep_under`, replaced by
    make(bang, label, path, fragment)."""

    def fix(m: re.Match) -> str:
        bang, label, target = m.groups()
        if not is_relative(target):
            return m.group(0)
        path, fragment = repo_path(target, doc)
        if keep_under and (path + "/").startswith(keep_under.rstrip("/") + "/"):
            return m.group(0)
        return make(bang, label, path, fragment)

    return LINK.sub(fix, text)


def absolute_links(text: str, doc: str, urls: dict[str, str], keep_under: str | None = None) -> str:
    """`text` (the markdown file at repository path `doc`) with every relative link and image made absolute, but
    those into `keep_under`, a folder whose files travel with the text (a model's, uploaded whole to its Hub repo)."""
    base, raw = file_base(urls), raw_base(urls)
    return _rewrite(
        text,
        doc,
        keep_under,
        lambda bang, label, path, frag: f"{bang}[{label}]({(raw if bang else base) + path}{frag})",
    )


def plain_links(text: str, doc: str, keep_under: str | None = None) -> str:
    """`text` with every relative link that leaves `keep_under` turned into its label and its repository path in
    code: for a card while the code's public address is not set (no link may point at a placeholder)."""

    def plain(bang: str, label: str, path: str, fragment: str) -> str:
        return label if label.strip("`") == path else f"{label} (`{path}` in the source)"

    return _rewrite(text, doc, keep_under, plain)
