#!/usr/bin/env python3
"""Writes bench/cornell-box-embree.pbrt from Embree's tutorial Cornell box (run once).

Reads cornell_box.obj / .mtl / .ecs of Debian's embree-tools
(/usr/share/doc/embree3/models): every face that the OBJ does not comment out (the
area-light quad and the front wall are commented out there), the diffuse colour Kd of
each material, the point light (-pointlight x y z r g b) and the camera (-vp -vi -vu -fov,
fov vertical). Quads become two triangles (0 1 2) (0 2 3). Usage:
    bench/convert-embree-cornell.py [MODELS_DIR] > bench/cornell-box-embree.pbrt
"""
import gzip
import os
import sys


def open_text(path):
    if not os.path.exists(path) and os.path.exists(path + ".gz"):
        path += ".gz"
    return gzip.open(path, "rt") if path.endswith(".gz") else open(path)


def main():
    models = sys.argv[1] if len(sys.argv) > 1 else "/usr/share/doc/embree3/models"
    kd = {}
    cur = None
    for line in open_text(os.path.join(models, "cornell_box.mtl")):
        w = line.split()
        if not w:
            continue
        if w[0] == "newmtl":
            cur = w[1]
        elif w[0] == "Kd" and cur:
            kd[cur] = [float(x) for x in w[1:4]]
    ecs = open_text(os.path.join(models, "cornell_box.ecs")).read().split()
    opt = {}
    i = 0
    while i < len(ecs):
        key = ecs[i].lstrip("-")
        n = {"i": 1, "pointlight": 6, "vp": 3, "vi": 3, "vu": 3, "fov": 1}.get(key, 0)
        opt[key] = ecs[i + 1:i + 1 + n]
        i += 1 + n
    verts = []
    meshes = []  # (object name, material, [triangles as vertex indices])
    obj, mat = "", "white"
    for line in open_text(os.path.join(models, opt.get("i", ["cornell_box.obj"])[0])):
        w = line.split()
        if not w or w[0].startswith("#"):
            continue
        if w[0] == "o":
            obj = w[1]
        elif w[0] == "usemtl":
            mat = w[1]
        elif w[0] == "v":
            verts.append([float(x) for x in w[1:4]])
        elif w[0] == "f":
            idx = [int(x.split("/")[0]) for x in w[1:]]
            idx = [k - 1 if k > 0 else len(verts) + k for k in idx]
            if not meshes or meshes[-1][0] != obj or meshes[-1][1] != mat:
                meshes.append((obj, mat, []))
            for k in range(1, len(idx) - 1):
                meshes[-1][2].append((idx[0], idx[k], idx[k + 1]))
    vp, vi, vu = (" ".join(opt[k]) for k in ("vp", "vi", "vu"))
    fov = opt["fov"][0]
    lx, ly, lz, lr, lg, lb = opt["pointlight"]
    out = sys.stdout
    out.write("# Embree 3's tutorial Cornell box (cornell_box.obj/.mtl/.ecs of Debian's embree-tools),\n")
    out.write("# converted by bench/convert-embree-cornell.py for bench/peers: the same geometry, the\n")
    out.write("# diffuse colours Kd, the point light and the camera (Embree's fov is vertical; square\n")
    out.write("# images make it pbrt's too). Embree's tutorial camera is right-handed: Scale -1 1 1.\n")
    out.write('Film "rgb" "integer xresolution" [ 512 ] "integer yresolution" [ 512 ]\n')
    out.write('    "string filename" [ "cornell-box-embree.exr" ]\n')
    out.write('Sampler "independent" "integer pixelsamples" [ 16 ]\n')
    out.write('Integrator "path" "integer maxdepth" [ 1 ]\n')
    out.write("Scale -1 1 1\n")
    out.write("LookAt %s  %s  %s\n" % (vp, vi, vu))
    out.write('Camera "perspective" "float fov" [ %s ]\n\n' % fov)
    out.write("WorldBegin\n")
    out.write('LightSource "point" "point3 from" [ %s %s %s ] "rgb I" [ %s %s %s ]\n\n' % (lx, ly, lz, lr, lg, lb))
    for name in sorted(set(m for _, m, _ in meshes)):
        r, g, b = kd.get(name, [0.5, 0.5, 0.5])
        out.write('MakeNamedMaterial "%s" "string type" "diffuse" "rgb reflectance" [ %g %g %g ]\n' % (name, r, g, b))
    for obj, mat, tris in meshes:
        used = sorted(set(v for t in tris for v in t))
        remap = {v: k for k, v in enumerate(used)}
        out.write('\n# %s\nNamedMaterial "%s"\nShape "trianglemesh"\n' % (obj, mat))
        out.write('    "point3 P" [ %s ]\n' % " ".join("%g %g %g" % tuple(verts[v]) for v in used))
        out.write('    "integer indices" [ %s ]\n' % " ".join("%d %d %d" % tuple(remap[v] for v in t) for t in tris))


if __name__ == "__main__":
    main()
