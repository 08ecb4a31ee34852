"""python -m tessera info|verify ARCHIVE: the CLI's info and verify (docs/cli.md), through the
Python package, with its exit codes: 0 success, 1 an error (one line on stderr,
`tessera: MESSAGE`), 2 a bad command line, 3 verify found faults or the archive is corrupt."""

from __future__ import annotations

import argparse
import json
import sys

import tessera


def _info(archive: tessera.Archive, as_json: bool, levels: bool) -> None:
    if as_json:
        images = []
        for info in archive.images:
            entry = {"name": info.name, "width": info.width, "height": info.height,
                     "channels": info.channels, "sample_type": info.sample_type,
                     "tile_size": info.tile_size,
                     "border": info.border, "level_count": info.level_count,
                     "codec": info.codec}
            if levels:
                entry["levels"] = info.levels
            images.append(entry)
        print(json.dumps({"archive": archive.name, "file_bytes": archive.file_bytes,
                          "images": images, "metadata": archive.metadata}, indent=2))
        return
    print(f"{archive.name}: {archive.file_bytes} bytes, {len(archive.images)} image(s)")
    for index, info in enumerate(archive.images):
        print(f"image {index} '{info.name}': {info.width} x {info.height} px, "
              f"{info.channels} channel(s) of {info.sample_type}, tiles {info.tile_size} px, "
              f"border {info.border}, {info.level_count} levels, codec {info.codec}")
        if levels:
            for level in info.levels:
                print(f"  level {level['level']}: {level['width']} x {level['height']} px, "
                      f"{level['tiles_x']} x {level['tiles_y']} tiles")


def _verify(archive: tessera.Archive, as_json: bool, decode: bool, quiet: bool) -> int:
    report = archive.verify(decode=decode, check=False)
    if as_json:
        print(json.dumps({"ok": report.ok, "fault_count": report.fault_count,
                          "faults": report.faults, "tiles_checked": report.tiles_checked,
                          "payloads_checked": report.payloads_checked,
                          "payload_bytes": report.payload_bytes,
                          "pages_checked": report.pages_checked}, indent=2))
    for fault in report.faults:
        print(fault, file=sys.stderr)
    if report.ok and not quiet and not as_json:
        print(f"{archive.name}: OK ({report.tiles_checked} tiles, {report.payloads_checked} "
              f"payloads, {report.payload_bytes} bytes, {report.pages_checked} directory pages)")
    return 0 if report.ok else 3


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m tessera",
                                     description="Inspect and verify Tessera archives.")
    commands = parser.add_subparsers(dest="command", required=True)
    info = commands.add_parser("info", help="print an archive's images and levels")
    info.add_argument("archive", help="path or http(s):// URL")
    info.add_argument("--json", action="store_true")
    info.add_argument("--no-levels", action="store_true")
    verify = commands.add_parser("verify", help="check every checksum and decode every tile")
    verify.add_argument("archive", help="path or http(s):// URL")
    verify.add_argument("--json", action="store_true")
    verify.add_argument("--no-decode", action="store_true")
    verify.add_argument("-q", "--quiet", action="store_true")
    try:
        args = parser.parse_args(argv)
    except SystemExit as exit_:  # argparse exits 2 on a bad command line, 0 on --help
        return int(exit_.code or 0)
    try:
        archive = tessera.open(args.archive)
        if args.command == "info":
            _info(archive, args.json, not args.no_levels)
            return 0
        return _verify(archive, args.json, not args.no_decode, args.quiet)
    except tessera.CorruptError as error:
        print(f"tessera: {error}", file=sys.stderr)
        return 3
    except tessera.Error as error:
        print(f"tessera: {error}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
