"""Writes the installable add-on zip (Blender: Edit > Preferences > Add-ons
> Install…): `python3 clients/blender/build_zip.py [OUT.zip]`, by default
`dend_blender.zip` next to this file."""

import pathlib
import sys
import zipfile

HERE = pathlib.Path(__file__).resolve().parent


def build(out: pathlib.Path) -> pathlib.Path:
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as z:
        for f in sorted((HERE / "dend_blender").glob("*.py")):
            z.write(f, f"dend_blender/{f.name}")
    return out


if __name__ == "__main__":
    print(build(pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else HERE / "dend_blender.zip"))
