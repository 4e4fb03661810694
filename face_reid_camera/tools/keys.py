"""face-reid-keys: make the camera network's key (one per network, copied to every host of it).

    face-reid-keys new ~/.config/face_reid/network.key

writes 32 random bytes as hex, mode 0600 (never overwrites). Give the same file to every camera node and the
master (``network_key_path``); copy it between hosts over a channel you trust (scp, a config manager), and keep
it 0600: whoever reads it can read and send frames.
"""

from __future__ import annotations

import argparse
import sys

from face_reid_camera.common.sealing import load_network_key, write_network_key


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="face-reid-keys", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    new = sub.add_parser("new", help="write a new random network key (mode 0600)")
    new.add_argument("path", help="the key file to write, e.g. ~/.config/face_reid/network.key")
    new.add_argument("--force", action="store_true", help="overwrite an existing key (every host needs the new one)")
    check = sub.add_parser("check", help="check that a key file is usable (private, well-formed)")
    check.add_argument("path", help="the key file to check")
    args = parser.parse_args(argv)
    try:
        if args.command == "new":
            path = write_network_key(args.path, overwrite=args.force)
            print(f"wrote a new network key to {path} (mode 0600); give it to every host as network_key_path")
        else:
            load_network_key(args.path)
            print(f"{args.path}: a usable network key")
    except ValueError as exc:
        print(f"face-reid-keys: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # e.g. --force onto a folder, a parent folder that cannot be made
        print(f"face-reid-keys: {exc.filename or args.path}: {exc.strerror or exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
