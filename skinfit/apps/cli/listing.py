"""What the listing commands (``skinfit models``, ``priors``, ``datasets``) share: the cards
found on the search path, where each is from, and the error when there are none."""

from skinfit.io.paths import entries, search_path

__all__ = ["NothingFound", "search_entries", "origin", "from_line"]


class NothingFound(Exception):
    """A listing command found nothing: message printed, exit status 1."""


def search_entries(kind, args):
    """Search-path entries of ``kind`` (id -> Entry); none found: say where it looked, exit 1."""
    found = entries(kind)
    if not found:
        looked = "\n".join(f"  {r.path / kind}  ({r.origin})" for r in search_path())
        raise NothingFound(f"skinfit: no {kind} found; searched:\n{looked}\n"
                           f"(add folders with --path DIR or ${'SKINFIT_PATH'}; see `skinfit --help`)")
    if getattr(args, "verbose", False) and not args.json:
        print("search path (first match wins):")
        for r in search_path():
            print(f"  {r.path / kind}  ({r.origin})")
        print()
    return found


def origin(entry):
    """Where a card was found: its path, the search-path root's origin and the cards it shadows."""
    return {"path": str(entry.path), "origin": entry.root.origin,
            "shadows": [str(r.path) for r in entry.shadows]}


def from_line(row, args):
    """The ``from:`` line of a listed card (``--verbose`` only)."""
    if not getattr(args, "verbose", False):
        return ""
    shadow = f"; shadows {', '.join(row['shadows'])}" if row["shadows"] else ""
    return f"\n  from: {row['path']} ({row['origin']}{shadow})"
