"""The command line of the resumable studies in results/cell: ``--out F`` (default: the committed
JSON next to the script) and ``--missing`` (run only the cases F does not hold yet); the JSON is
rewritten after every case, so an interrupted study loses one case at most."""
import argparse
import json
from pathlib import Path


def parse(doc: str, default: Path, with_full: bool = False) -> tuple:
    """(output path, rows already done) from the command line of a study with docstring ``doc``;
    ``with_full``: the study also takes ``--full`` (its long cases), returned third."""
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--out", type=Path, default=default)
    ap.add_argument("--missing", action="store_true",
                    help="run only the cases the output file does not hold yet")
    if with_full:
        ap.add_argument("--full", action="store_true", help="also run the long cases")
    args = ap.parse_args()
    rows = (json.loads(args.out.read_text())["rows"]
            if args.missing and args.out.exists() else [])
    return (args.out, rows, args.full) if with_full else (args.out, rows)


def write(out: Path, rows: list, command: str, note: str) -> None:
    out.write_text(json.dumps({"rows": rows, "command": command, "note": note}, indent=1) + "\n")
