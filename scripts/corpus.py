#!/usr/bin/env python3
"""Real third-party models, fetched from package registries and lit as users would light them.

    python3 scripts/corpus.py [--references]

Fetches (once; cached in cache/corpus/, checked by SHA-256) and writes scenes/corpus/:

- monastery.obj: the samurai monastery in pybullet_data (PyPI `pybullet` 3.2.7, under its zlib
  licence; 124,990 triangles as shipped, Kd 0.64 everywhere) on a ground quad under an
  emitting sky quad; monastery-piece.obj: the faces of it within a 20 m square (a 6.7k-triangle
  piece under a ground and sky of its own size); monastery-village.obj: eight of it, four by
  two, turned a quarter each (998k triangles).
- living-room.obj: a 8 x 6 x 3 m room furnished with Blend Swap models of Debian's
  `sweethome3d-furniture` 1.8-1 (its BlendSwap-CC-0 library, CC0), lit by a ceiling lamp.
- teddy.obj: the teddy bear of that library (curved triangle soup) on a floor under a lamp.

The models' triangles are written as shipped (Kd 1 and all); only positions are placed and
scaled. With --references, also writes each scene's path-traced reference
(`radcast reference --probes 4000 --samples 65536`) to scenes/corpus/reference/, where
`radcast bench --error` looks for it (for a scene without one it makes a smaller one, 1,000
probes x 4,096 paths).
"""

import argparse
import hashlib
import io
import math
import pathlib
import re
import subprocess
import sys
import tarfile
import zipfile

ROOT = pathlib.Path(__file__).resolve().parent.parent
CACHE = ROOT / "cache" / "corpus"
OUT = ROOT / "scenes" / "corpus"

PYBULLET = ("pybullet-3.2.7-cp311-cp311-manylinux_2_17_x86_64.manylinux2014_x86_64.whl",
            ["pip", "download", "pybullet==3.2.7", "--no-deps", "--only-binary", ":all:",
             "--python-version", "3.11", "--platform", "manylinux2014_x86_64"])
FURNITURE = ("sweethome3d-furniture_1.8-1_all.deb",
             ["apt-get", "download", "sweethome3d-furniture=1.8-1"])
SHA256 = {
    PYBULLET[0]: "5d858abf7c12a21ef3ed351cf81dac1b5e486ec25c9ab59bfc84beb89034edff",
    FURNITURE[0]: "3ccb90c63f9525e887a767b9cd5c8b6933b8b6b2973a615a5359ee68a2118668",
}


def fetch(name, command):
    """The cached package file `name`, downloaded by `command` when absent."""
    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / name
    if not path.exists():
        print(f"fetching {name}", file=sys.stderr)
        subprocess.run(command, cwd=CACHE, check=True, stdout=subprocess.DEVNULL)
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    if digest != SHA256[name]:
        sys.exit(f"{path}: SHA-256 {digest}, expected {SHA256[name]} (delete it to fetch again)")
    return path


class Obj:
    """An OBJ being written: positions, texture coordinates and faces of several models."""

    def __init__(self, name):
        self.name = name
        self.lines = [f"# {name}: written by scripts/corpus.py", f"mtllib {name}.mtl"]
        self.materials = []
        self.positions = 0
        self.texcoords = 0

    def material(self, name, kd, ke=(0, 0, 0), extra=()):
        self.materials += [f"newmtl {name}", "Kd %g %g %g" % tuple(kd), "Ke %g %g %g" % tuple(ke),
                           *extra, ""]

    def quad(self, obj_name, material, corners):
        """A quad, counter-clockwise seen from its front (the side it emits to)."""
        self.lines += [f"o {obj_name}", f"usemtl {material}"]
        self.lines += ["v %.6f %.6f %.6f" % c for c in corners]
        n = self.positions
        self.lines.append(f"f {n + 1} {n + 2} {n + 3} {n + 4}")
        self.positions += 4

    def box(self, obj_name, material, low, high):
        """An open box seen from inside: floor, ceiling and four walls facing in."""
        (x0, y0, z0), (x1, y1, z1) = low, high
        self.lines += [f"o {obj_name}", f"usemtl {material}"]
        corners = [(x, y, z) for x in (x0, x1) for y in (y0, y1) for z in (z0, z1)]
        self.lines += ["v %.6f %.6f %.6f" % c for c in corners]
        n = self.positions + 1
        # Corner index: 4x + 2y + z (0 low, 1 high); each quad wound to face the inside.
        for quad in [(0, 4, 6, 2), (1, 3, 7, 5), (0, 1, 5, 4), (2, 6, 7, 3), (0, 2, 3, 1),
                     (4, 5, 7, 6)]:
            self.lines.append("f " + " ".join(str(n + i) for i in quad))
        self.positions += 8

    def model(self, obj_name, source, mtl, place, keep=lambda corners: True):
        """Appends the OBJ text `source` with positions mapped by `place`, materials prefixed
        with `obj_name` (their MTL text `mtl`), faces kept where `keep` says so; returns how
        many faces were kept and the bounds of their corners."""
        positions, texcoords = [], []
        faces = []
        material = None
        for line in source.splitlines():
            words = line.split()
            if not words:
                continue
            if words[0] == "v":
                positions.append(tuple(float(w) for w in words[1:4]))
            elif words[0] == "vt":
                texcoords.append(" ".join(words[1:3]))
            elif words[0] == "usemtl":
                material = words[1] if len(words) > 1 else None
            elif words[0] == "f":
                corners = [w.split("/") for w in words[1:]]
                faces.append((material, corners))
        placed = [place(p) for p in positions]
        self.lines.append(f"o {obj_name}")
        self.lines += ["v %.6f %.6f %.6f" % p for p in placed]
        self.lines += [f"vt {t}" for t in texcoords]
        current = None
        kept = 0
        low, high = [float("inf")] * 3, [float("-inf")] * 3
        for material, corners in faces:
            index = [int(c[0]) for c in corners]
            index = [i - 1 if i > 0 else len(positions) + i for i in index]
            if not keep([placed[i] for i in index]):
                continue
            for i in index:
                low = [min(a, b) for a, b in zip(low, placed[i])]
                high = [max(a, b) for a, b in zip(high, placed[i])]
            if material != current:
                self.lines.append(f"usemtl {obj_name}.{material}")
                current = material
            words = []
            for i, c in zip(index, corners):
                word = str(self.positions + i + 1)
                if len(c) > 1 and c[1]:
                    t = int(c[1])
                    t = t - 1 if t > 0 else len(texcoords) + t
                    word += f"/{self.texcoords + t + 1}"
                words.append(word)
            self.lines.append("f " + " ".join(words))
            kept += 1
        self.positions += len(positions)
        self.texcoords += len(texcoords)
        self.materials += re.sub(r"(?m)^newmtl\s+(.*)$", rf"newmtl {obj_name}.\1", mtl).splitlines()
        self.materials.append("")
        return kept, (low, high)

    def write(self):
        OUT.mkdir(parents=True, exist_ok=True)
        (OUT / f"{self.name}.obj").write_text("\n".join(self.lines) + "\n")
        (OUT / f"{self.name}.mtl").write_text("\n".join(self.materials) + "\n")
        return OUT / f"{self.name}.obj"


def bounds(source):
    points = [tuple(float(w) for w in line.split()[1:4])
              for line in source.splitlines() if line.startswith("v ")]
    return [min(p[k] for p in points) for k in range(3)], [max(p[k] for p in points) for k in range(3)]


def sky_and_ground(scene, low, high, sky_height):
    """A ground quad at the model's foot three times its footprint, and above it at
    `sky_height` a sky quad five times the footprint emitting down (W/m^2)."""
    cx, cz = (low[0] + high[0]) / 2, (low[2] + high[2]) / 2
    half = max(high[0] - low[0], high[2] - low[2]) / 2
    scene.material("ground", (0.3, 0.3, 0.3))
    scene.material("sky", (0, 0, 0), (1, 1, 1))
    g, y = 3 * half, low[1]
    scene.quad("ground", "ground", [(cx - g, y, cz - g), (cx - g, y, cz + g), (cx + g, y, cz + g),
                                    (cx + g, y, cz - g)])
    s = 5 * half
    scene.quad("sky", "sky", [(cx - s, sky_height, cz - s), (cx + s, sky_height, cz - s),
                              (cx + s, sky_height, cz + s), (cx - s, sky_height, cz + s)])


def monastery(wheel):
    with zipfile.ZipFile(wheel) as z:
        source = z.read("pybullet_data/samurai_monastry.obj").decode()
        mtl = z.read("pybullet_data/samurai_monastry.mtl").decode()
    _, high = bounds(source)
    written = []
    for name, keep in [("monastery", lambda c: True),
                       ("monastery-piece", lambda c: all(abs(p[0]) < 10 and abs(p[2] - 20) < 10
                                                         for p in c))]:
        scene = Obj(name)
        kept, (low, top) = scene.model("monastery", source, mtl, lambda p: p, keep)
        sky_and_ground(scene, low, top, high[1] * 3)
        written.append((scene.write(), kept))
    written.append(village(source, mtl))
    return written


def village(source, mtl):
    """Eight monasteries, four by two, each turned a quarter more than the last and a tenth of
    its footprint from the next: a real model of a million triangles."""
    low, high = bounds(source)
    span = [1.1 * (high[k] - low[k]) for k in (0, 2)]
    centre = [(low[k] + high[k]) / 2 for k in (0, 2)]
    # A quarter turn keeps the footprint in its cell only where it is square: use the larger
    # side for both.
    cell = max(span)
    scene = Obj("monastery-village")
    kept, first, last = 0, [float("inf")] * 3, [float("-inf")] * 3
    for i in range(8):
        x, z = (i % 4 - 1.5) * cell, (i // 4 - 0.5) * cell
        c, s = [(1, 0), (0, 1), (-1, 0), (0, -1)][i % 4]

        def place(p, x=x, z=z, c=c, s=s):
            u, v = p[0] - centre[0], p[2] - centre[1]
            return (x + c * u + s * v, p[1], z - s * u + c * v)

        faces, (lo, hi) = scene.model(f"monastery-{i}", source, mtl, place)
        kept += faces
        first = [min(a, b) for a, b in zip(first, lo)]
        last = [max(a, b) for a, b in zip(last, hi)]
    sky_and_ground(scene, first, last, high[1] * 3)
    return scene.write(), kept


FURNISHINGS = [
    # (model, x, z, degrees about y): centre of its footprint on the floor, metres.
    ("bed2", -2.9, -1.8, 0), ("armchair", 2.6, 1.9, 200), ("armchair", 3.4, 1.2, 240),
    ("oakTable", 0.2, -0.2, 0), ("stool", 0.2, 0.7, 180), ("stool", 0.2, -1.1, 0),
    ("bookcase", -0.6, -2.75, 0), ("cupboard", 3.78, -0.6, 270),
    ("shelves", -3.78, 1.2, 90), ("teddyBear", -2.9, -0.5, 0),
]


def furniture_catalogue(deb):
    """The BlendSwap-CC-0 library out of the Debian package: a ZipFile and its catalogue."""
    data = subprocess.run(["dpkg-deb", "--fsys-tarfile", str(deb)], check=True,
                          capture_output=True).stdout
    with tarfile.open(fileobj=io.BytesIO(data)) as tar:
        member = tar.extractfile("./usr/share/sweethome3d/furniture/BlendSwap-CC-0.sh3f")
        library = zipfile.ZipFile(io.BytesIO(member.read()))
    properties = library.read("PluginFurnitureCatalog.properties").decode("latin-1")
    catalogue = {}
    for key, n, value in re.findall(r"(?m)^(\w+)#(\d+)=(.*)$", properties):
        catalogue.setdefault(n, {})[key] = value.strip()
    by_model = {pathlib.PurePosixPath(e["model"]).stem: e for e in catalogue.values() if "model" in e}
    return library, by_model


def furnished(library, by_model, name, pieces, room, lamp):
    """A room (x, z half sizes, height; metres) with `pieces` standing on its floor and a lamp
    quad of `lamp` metres a side under the ceiling."""
    hx, hz, height = room
    scene = Obj(name)
    scene.material("wall", (0.7, 0.7, 0.68))
    scene.box("room", "wall", (-hx, 0, -hz), (hx, height, hz))
    scene.material("lamp", (0.8, 0.8, 0.8), (30, 28, 24))
    y, l = height - 0.01, lamp / 2
    scene.quad("lamp", "lamp", [(-l, y, -l), (l, y, -l), (l, y, l), (-l, y, l)])
    triangles = 0
    for i, (model, x, z, degrees) in enumerate(pieces):
        entry = by_model[model]
        path = entry["model"].lstrip("/")
        source = library.read(path).decode("latin-1")
        mtl_path = re.search(r"(?m)^mtllib\s+(.*)$", source)
        mtl = library.read(str(pathlib.PurePosixPath(path).parent / mtl_path.group(1).strip())) \
            .decode("latin-1") if mtl_path else ""
        # Textures beside the scene, where its MTL names them.
        for texture in re.findall(r"(?m)^\s*map_Kd\s+(?:.*\s)?(\S+)\s*$", mtl):
            member = str(pathlib.PurePosixPath(path).parent / texture)
            if member in library.namelist():
                (OUT / texture).parent.mkdir(parents=True, exist_ok=True)
                (OUT / texture).write_bytes(library.read(member))
        low, high = bounds(source)
        # Sweet Home 3D scales a model to its catalogue size (cm), y up.
        size = [float(entry["width"]) / 100, float(entry["height"]) / 100,
                float(entry["depth"]) / 100]
        scale = [size[k] / max(high[k] - low[k], 1e-9) for k in range(3)]
        c, s = math.cos(math.radians(degrees)), math.sin(math.radians(degrees))

        def place(p, low=low, high=high, scale=scale, c=c, s=s, x=x, z=z):
            local = [(p[k] - (low[k] + high[k]) / 2) * scale[k] for k in range(3)]
            up = (p[1] - low[1]) * scale[1]
            return (x + c * local[0] + s * local[2], up, z - s * local[0] + c * local[2])

        triangles += scene.model(f"{model}-{i}", source, mtl, place)[0]
    return scene.write(), triangles


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--references", action="store_true",
                        help="also path-trace each scene's reference (minutes each)")
    args = parser.parse_args()
    written = monastery(fetch(*PYBULLET))
    library, by_model = furniture_catalogue(fetch(*FURNITURE))
    written.append(furnished(library, by_model, "living-room", FURNISHINGS, (4, 3, 3), 0.6))
    written.append(furnished(library, by_model, "teddy", [("teddyBear", 0, 0, 0)], (1, 1, 1.5),
                             0.3))
    for path, faces in written:
        print(f"{path.relative_to(ROOT)}: {faces} model faces")
    if args.references:
        radcast = ROOT / "target" / "release" / "radcast"
        for path, _ in written:
            reference = path.parent / "reference" / f"{path.stem}.json"
            if not reference.exists():
                subprocess.run([str(radcast), "reference", str(path), "--probes", "4000",
                                "--samples", "65536", "--out", str(reference)], check=True)


if __name__ == "__main__":
    main()
