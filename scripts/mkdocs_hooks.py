"""mkdocs hook (mkdocs.yml, ``hooks:``): the API reference page, one section per public name of ``uq``.

The names and the modules that define them are read from the package (``uq._API``, the table
behind its lazy attributes) when the site is built, so a new public name appears on
docs/reference.md without editing it, and a name that moves to another module is still found.
mkdocstrings then renders each from its docstring.
"""

from __future__ import annotations

MARKER = "<!-- api-reference"
PAGE = "reference.md"


def public_names() -> list[tuple[str, str]]:
    """(public name, dotted path of the object that defines it), sorted by name."""
    import uq

    out = []
    for name, target in uq._API.items():
        module, attr = target if isinstance(target, tuple) else (target, name)
        out.append((name, f"uq.{module}.{attr}"))
    return sorted(out)


def reference_markdown() -> str:
    """One section per public name: a heading ``uq.NAME`` and the mkdocstrings directive."""
    return "\n".join(
        f"## `uq.{name}`\n\n::: {path}\n    options:\n      show_root_heading: false\n"
        for name, path in public_names()
    )


def on_page_markdown(markdown: str, page, config, files) -> str:
    if page.file.src_uri != PAGE:
        return markdown
    lines = markdown.splitlines()
    at = [i for i, line in enumerate(lines) if line.startswith(MARKER)]
    if len(at) != 1:
        raise ValueError(f"docs/{PAGE} must hold one line starting with {MARKER!r}")
    lines[at[0]] = reference_markdown()
    return "\n".join(lines) + "\n"


def fence_doctests(text: str) -> str:
    """Wrap each doctest (a ``>>>`` line up to the next blank line) in a ``pycon`` code fence, so
    the examples of the docstrings render as code, not as Markdown (``x[0]`` is no link)."""
    out, inside = [], False
    for line in text.splitlines():
        starts = line.lstrip().startswith(">>>")
        if starts and not inside:
            out.append(line[: len(line) - len(line.lstrip())] + "```pycon")
            inside = True
        elif inside and not line.strip():
            out.append(_fence_indent(out))
            inside = False
        out.append(line)
    if inside:
        out.append(_fence_indent(out))
    return "\n".join(out)


def _fence_indent(lines: list[str]) -> str:
    """The closing fence, indented as the opening one."""
    opening = next(ln for ln in reversed(lines) if ln.lstrip() == "```pycon")
    return opening[: len(opening) - len(opening.lstrip())] + "```"


try:  # the mkdocstrings handler loads this class as a griffe extension (mkdocs.yml)
    import griffe

    class DoctestFences(griffe.Extension):
        """Griffe extension: the docstrings' doctests as code blocks (:func:`fence_doctests`)."""

        def on_instance(self, *, node, obj, agent, **kwargs) -> None:
            if obj.docstring is not None:
                obj.docstring.value = fence_doctests(obj.docstring.value)

except ImportError:  # griffe comes with the docs extra; the hook itself does not need it
    pass
