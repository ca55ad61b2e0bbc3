#!/usr/bin/env python3
"""Independent reference for the cantilever of tests/sim/bbar_test.cpp: CalculiX (Debian's calculix-ccx) with
20-node reduced-integration hexahedra (C3D20R, quadratic: neither shear nor volumetric locking at these sizes).

The beam is 0.1 x 0.02 x 0.02 m (x from 0 to 0.1, y and z from -0.01 to 0.01), E = 1e7 Pa, rho = 1000 kg/m^3, clamped
(all three displacements) on the face x = 0, loaded by gravity 9.81 m/s^2 along -z; linear static analysis. Prints
the downward deflection of the tip centre (0.1, 0, 0) in m for each nu and mesh, as JSON.

  python3 tests/sim/reference/cantilever_ccx.py [--meshes 20x4x4,40x8x8,60x12x12] [--nu 0.3,0.49]
"""
import argparse
import json
import os
import subprocess
import tempfile

L, B, E, RHO, G = 0.1, 0.02, 1e7, 1000.0, 9.81


def deck(nx, ny, nz, nu):
    # Nodes on the half-spacing grid, numbered only where an element uses them.
    ids = {}
    def node(i, j, k):
        key = (i, j, k)
        if key not in ids:
            ids[key] = len(ids) + 1
        return ids[key]
    elems = []
    for ex in range(nx):
        for ey in range(ny):
            for ez in range(nz):
                i, j, k = 2 * ex, 2 * ey, 2 * ez
                c = [(i, j, k), (i + 2, j, k), (i + 2, j + 2, k), (i, j + 2, k),
                     (i, j, k + 2), (i + 2, j, k + 2), (i + 2, j + 2, k + 2), (i, j + 2, k + 2)]
                mid = lambda a, b: tuple((p + q) // 2 for p, q in zip(c[a], c[b]))
                edges = [(0, 1), (1, 2), (2, 3), (3, 0), (4, 5), (5, 6), (6, 7), (7, 4), (0, 4), (1, 5), (2, 6), (3, 7)]
                pts = c + [mid(a, b) for a, b in edges]
                elems.append([node(*p) for p in pts])
    lines = ["*HEADING", "cantilever reference", "*NODE"]
    for (i, j, k), n in sorted(ids.items(), key=lambda t: t[1]):
        lines.append(f"{n}, {i * L / (2 * nx):.12g}, {-B / 2 + j * B / (2 * ny):.12g}, {-B / 2 + k * B / (2 * nz):.12g}")
    lines.append("*ELEMENT, TYPE=C3D20R, ELSET=EALL")
    for e, conn in enumerate(elems, 1):
        # At most 16 entries per line in an *ELEMENT data line: split after 15 nodes.
        lines.append(f"{e}, " + ", ".join(map(str, conn[:15])) + ",")
        lines.append(", ".join(map(str, conn[15:])))
    lines.append("*NSET, NSET=CLAMP")
    clamp = [n for (i, j, k), n in ids.items() if i == 0]
    for s in range(0, len(clamp), 16):
        lines.append(", ".join(map(str, clamp[s:s + 16])) + ",")
    tip = ids[(2 * nx, ny, nz)]
    lines += ["*NSET, NSET=TIP", f"{tip},",
              "*MATERIAL, NAME=M", "*ELASTIC", f"{E}, {nu}", "*DENSITY", f"{RHO}",
              "*SOLID SECTION, ELSET=EALL, MATERIAL=M",
              "*BOUNDARY", "CLAMP, 1, 3, 0.0",
              "*STEP", "*STATIC", "*DLOAD", f"EALL, GRAV, {G}, 0., 0., -1.",
              "*NODE PRINT, NSET=TIP", "U", "*END STEP"]
    return "\n".join(lines) + "\n"


def tip_deflection(nx, ny, nz, nu):
    with tempfile.TemporaryDirectory() as d:
        with open(os.path.join(d, "beam.inp"), "w") as f:
            f.write(deck(nx, ny, nz, nu))
        subprocess.run(["ccx", "beam"], cwd=d, check=True, stdout=subprocess.DEVNULL)
        rows = open(os.path.join(d, "beam.dat")).read().split("displacements")[1].split("\n")
        for row in rows:
            parts = row.split()
            if len(parts) == 4:
                return -float(parts[3])
    raise RuntimeError("no tip displacement in beam.dat")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--meshes", default="20x4x4,40x8x8,60x12x12")
    ap.add_argument("--nu", default="0.3,0.49")
    a = ap.parse_args()
    out = {}
    for nu in map(float, a.nu.split(",")):
        for m in a.meshes.split(","):
            nx, ny, nz = map(int, m.split("x"))
            out[f"nu={nu} C3D20R {m}"] = tip_deflection(nx, ny, nz, nu)
    print(json.dumps(out, indent=2))


if __name__ == "__main__":
    main()
