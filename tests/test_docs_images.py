"""Every image the README and docs/*.md show exists and is made by one command from the
current code (scripts/make_docs_images.py), or is listed there as kept, with why."""

from __future__ import annotations

import importlib.util
from types import ModuleType

import pytest
from test_docs import DOCUMENTS, ROOT, relative_links


def script() -> ModuleType:
    path = ROOT / "scripts" / "make_docs_images.py"
    spec = importlib.util.spec_from_file_location("make_docs_images", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def linked_images() -> set[str]:
    found = set()
    for document in DOCUMENTS:
        for target in relative_links(document):
            path = (document.parent / target.partition("#")[0]).resolve()
            if path.suffix.lower() in (".png", ".jpg", ".jpeg", ".gif", ".svg"):
                found.add(str(path.relative_to(ROOT)))
    return found


def test_the_docs_show_images() -> None:
    assert {"docs/office.png", "docs/figure6.png"} <= linked_images()


def test_every_linked_image_exists_and_has_a_maker() -> None:
    make = script()
    linked = linked_images()
    assert all((ROOT / name).exists() for name in linked)
    unmade = linked - set(make.IMAGES) - set(make.KEPT)
    assert not unmade, f"no maker in scripts/make_docs_images.py for {sorted(unmade)}"
    assert not set(make.IMAGES) & set(make.KEPT)
    assert all(callable(maker) for maker in make.IMAGES.values())


def test_the_script_refuses_an_image_it_cannot_make() -> None:
    with pytest.raises(SystemExit):
        script().main(["--only", "docs/nothing.png"])
