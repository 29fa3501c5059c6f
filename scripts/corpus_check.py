#!/usr/bin/env python3
"""Loads and renders every scene of the public-scene corpus (scenes/corpus/,
provenance in scenes/corpus/SOURCES.md) with Penumbra and with Mitsuba 3,
compares the two images and writes the table docs/corpus.md.

A development tool, not a test (it needs Mitsuba 3; CI has none):

  export DRJIT_LIBLLVM_PATH=/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1
  ~/.cache/penumbra-mitsuba/venv/bin/python scripts/corpus_check.py \
      [--penumbra target/release/penumbra] [--spp 64] [--res 96] \
      [--variant scalar_rgb] [--only SUBSTRING] [--no-doc] [--doc-only]

For each scene (a corpus XML file that no other corpus file includes and
that does not sit in an include/ or fragments/ folder):

1. The corpus is copied twice under out/corpus/: `pristine/` (files as
   fetched) and `small/` (the same, with every film's literal or
   <default>-given width and height scaled down so that the larger side is
   at most --res pixels). Assets the scenes name that the corpus lacks
   (binary files that could not be fetched as text: serialized meshes,
   binary PLY, EXR/PNG/JPEG images, grid volumes) get a stand-in in both
   copies: a sphere, quad or cube mesh, a small gradient image, a smooth
   density grid (see `make_standin`). The scene files themselves are never
   edited in `pristine/`.
2. Penumbra loads the pristine scene (`penumbra params`): success, or its
   first error line.
3. Both renderers render the small copy twice (seeds 0 and 1, --spp
   samples per pixel, the scene's own sampler, integrator and sensor 0):
   Penumbra through its CLI, Mitsuba in a subprocess (so a crash or a
   timeout of one scene does not stop the run).
4. The comparison is variance-aware. Each renderer renders SEEDS
   independent images (Mitsuba's seeds far apart: its neighbouring seeds
   gave correlated images), averaged over 4x4 pixel blocks. Per block and
   channel, t = (P - M) / sqrt(var P + var M) with P, M the means over the
   seeds and var the variances of those means (sample variance / SEEDS).
   A scene matches when fewer than FRAC_MATCH of the block values have
   |t| > T_OUT and the image means agree within Z_MEAN standard errors
   (per-seed image means), or when the block-wise relative L2 difference
   is below REL_MATCH (noise-free scenes). A match whose relative L2
   difference exceeds NOISY (noise dominates) or whose images are black
   is `inconclusive`.
Outcomes: `mitsuba-fails` (excluded: Mitsuba 3 itself cannot render the
file as found, e.g. an asset without a stand-in, a polarised or custom
plugin), `refused` (Penumbra's first error line), `render-error`,
`match`, `differs`, `inconclusive`.
"""
import argparse
import json
import math
import os
import re
import shutil
import struct
import subprocess
import sys
import time
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
CORPUS = os.path.join(ROOT, 'scenes', 'corpus')
OUT = os.path.join(ROOT, 'out', 'corpus')
DOC = os.path.join(ROOT, 'docs', 'corpus.md')
FRAGMENT_DIRS = {'include', 'fragments', 'mts1-fragments', 'materials', 'illuminants'}
SEEDS = 4
MITSUBA_SEEDS = [17 + 7919 * k for k in range(SEEDS)]
T_OUT = 5.0
FRAC_MATCH = 0.03
Z_MEAN = 5.0
REL_MATCH = 0.01
NOISY = 0.25
NOTES_MARKER = '<!-- analysis: kept by scripts/corpus_check.py -->'
# Scenes whose Mitsuba render is made with another integrator, because
# Mitsuba 3.9.1's own is biased on them (the note says why; Penumbra still
# renders the file unchanged, with the scene's integrator).
MASK_BIAS = ("Mitsuba rendered with volpath: its path zeroes a camera path's radiance "
             "unless the path reaches a surface that did not sample a null lobe, so a "
             "mask's light is dropped when its sample passes through into empty space "
             "(scenes/conformance/README.md, mask_opacity)")
MITSUBA_INTEGRATOR = {
    f'mitsuba-data/tests/scenes/bsdf_spheres/{name}.xml':
        ({'type': 'volpath', 'max_depth': 3}, MASK_BIAS)
    for name in ('test_pointlight', 'test_arealight')
}
BLOCK = 4

# --------------------------------------------------------------------------
# Scene discovery and asset references


def corpus_files():
    out = []
    for d, _, files in os.walk(CORPUS):
        for f in files:
            if f.endswith('.xml'):
                out.append(os.path.relpath(os.path.join(d, f), CORPUS))
    return sorted(out)


def read(path):
    with open(path, encoding='utf-8', errors='replace') as f:
        return f.read()


def strip_comments(text):
    return re.sub(r'<!--.*?-->', '', text, flags=re.S)


def includes_of(rel, text):
    base = os.path.dirname(rel)
    out = []
    for m in re.finditer(r'<include\s+filename\s*=\s*"([^"]+)"', strip_comments(text)):
        out.append(os.path.normpath(os.path.join(base, m.group(1))))
    return out


def root_scenes(files):
    included = set()
    for rel in files:
        text = read(os.path.join(CORPUS, rel))
        for inc in includes_of(rel, text):
            included.add(inc)
        # an include may also be found relative to the top scene's folder
    roots = []
    for rel in files:
        parts = set(os.path.dirname(rel).split(os.sep))
        if rel in included or parts & FRAGMENT_DIRS or '.ipynb_checkpoints' in parts:
            continue
        if '<scene' not in read(os.path.join(CORPUS, rel)):
            continue
        roots.append(rel)
    return roots


def scene_closure(rel):
    """The scene file and the files it includes (found relative to the
    including file, then to the top scene), with their text."""
    top = os.path.dirname(rel)
    seen, order, todo = set(), [], [rel]
    while todo:
        r = todo.pop()
        if r in seen:
            continue
        seen.add(r)
        p = os.path.join(CORPUS, r)
        if not os.path.isfile(p):
            continue
        text = read(p)
        order.append((r, text))
        for m in re.finditer(r'<include\s+filename\s*=\s*"([^"]+)"', strip_comments(text)):
            a = os.path.normpath(os.path.join(os.path.dirname(r), m.group(1)))
            b = os.path.normpath(os.path.join(top, m.group(1)))
            todo.append(a if os.path.isfile(os.path.join(CORPUS, a)) else b)
    return order


def defaults_of(closure):
    d = {}
    for _, text in closure:
        for m in re.finditer(r'<default\s+name\s*=\s*"([^"]+)"\s+value\s*=\s*"([^"]*)"', text):
            d.setdefault(m.group(1), m.group(2))
    return d


def subst(value, defaults):
    return re.sub(r'\$(\w+)', lambda m: defaults.get(m.group(1), m.group(0)), value)


ASSET_RE = re.compile(r'<string\s+name\s*=\s*"filename"\s+value\s*=\s*"([^"]+)"')
SHAPE_INDEX_RE = re.compile(
    r'name\s*=\s*"filename"\s+value\s*=\s*"([^"]+\.serialized)"(.*?)</shape>', re.S)


def asset_refs(rel):
    """(path as written, substituted) of every filename the scene uses, and
    its <path> folders (relative to the top scene)."""
    closure = scene_closure(rel)
    defaults = defaults_of(closure)
    refs, paths = [], []
    for _, text in closure:
        t = strip_comments(text)
        for m in ASSET_RE.finditer(t):
            refs.append(subst(m.group(1), defaults))
        for m in re.finditer(r'<path\s+value\s*=\s*"([^"]+)"', t):
            paths.append(m.group(1))
    return closure, defaults, refs, paths


def shape_indices(closure):
    """Highest shape_index used per serialized file name."""
    hi = {}
    for _, text in closure:
        for m in SHAPE_INDEX_RE.finditer(strip_comments(text)):
            k = re.search(r'name\s*=\s*"shape_index"\s+value\s*=\s*"(\d+)"', m.group(2))
            hi[m.group(1)] = max(hi.get(m.group(1), 0), int(k.group(1)) if k else 0)
    return hi


# --------------------------------------------------------------------------
# Stand-in assets


def sphere_mesh(n_theta=16, n_phi=32):
    v, n, uv, f = [], [], [], []
    for i in range(n_theta + 1):
        th = math.pi * i / n_theta
        for j in range(n_phi + 1):
            ph = 2 * math.pi * j / n_phi
            p = (math.sin(th) * math.cos(ph), math.sin(th) * math.sin(ph), math.cos(th))
            v.append(p)
            n.append(p)
            uv.append((j / n_phi, 1 - i / n_theta))
    w = n_phi + 1
    for i in range(n_theta):
        for j in range(n_phi):
            a, b, c, d = i * w + j, i * w + j + 1, (i + 1) * w + j + 1, (i + 1) * w + j
            if i > 0:
                f.append((a, d, b))
            if i < n_theta - 1:
                f.append((b, d, c))
    return v, n, uv, f


def quad_mesh():
    v = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
    return v, [(0, 0, 1)] * 4, [(0, 0), (1, 0), (1, 1), (0, 1)], [(0, 1, 2), (0, 2, 3)]


def cube_mesh():
    v, n, uv, f = [], [], [], []
    for axis in range(3):
        for s in (-1, 1):
            base = len(v)
            # (u, w, axis) cyclic: every face wound counter-clockwise seen
            # from outside, so that the geometric normals point out (media
            # boundaries and one-sided emitters depend on it)
            u_ax, w_ax = (axis + 1) % 3, (axis + 2) % 3
            for (a, b) in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
                p = [0, 0, 0]
                p[axis], p[u_ax], p[w_ax] = s, a * s, b
                q = [0, 0, 0]
                q[axis] = s
                v.append(tuple(p))
                n.append(tuple(q))
                uv.append(((a + 1) / 2, (b + 1) / 2))
            f += [(base, base + 1, base + 2), (base, base + 2, base + 3)]
    return v, n, uv, f


def mesh_for(name):
    low = os.path.basename(name).lower()
    stem = os.path.splitext(low)[0]
    if any(k in low for k in ('rect', 'plane', 'quad', 'background', 'floor', 'ground', 'wall',
                              'plate', 'ceiling', 'back', 'luminaire')):
        v, n, uv, f = quad_mesh()
    elif 'cube' in low or 'box' in low:
        v, n, uv, f = cube_mesh()
    else:
        v, n, uv, f = sphere_mesh()
    if 'bunny' in low:
        # the scenes scale the (about 0.15 units tall) bunny by 12 or so
        return [(0.08 * a, 0.08 * b + 0.1, 0.08 * c) for a, b, c in v], n, uv, f
    if stem not in ('sphere', 'rectangle', 'plane', 'quad', 'cube'):
        # distinct files get distinct sizes and offsets: stand-ins of
        # different meshes placed alike must not coincide (coincident
        # surfaces are ill-posed)
        h = zlib.crc32(low.encode())
        r, dz = 0.55 + 0.4 * (h % 100) / 100, 0.3 * ((h // 100) % 7 - 3) / 3
        v = [(r * a, r * b, r * c + dz) for a, b, c in v]
    return v, n, uv, f


def write_obj(path, mesh):
    v, n, uv, f = mesh
    with open(path, 'w') as o:
        o.write('# stand-in written by scripts/corpus_check.py\n')
        o.writelines(f'v {a:.6f} {b:.6f} {c:.6f}\n' for a, b, c in v)
        o.writelines(f'vn {a:.6f} {b:.6f} {c:.6f}\n' for a, b, c in n)
        o.writelines(f'vt {a:.6f} {b:.6f}\n' for a, b in uv)
        o.writelines('f ' + ' '.join(f'{i + 1}/{i + 1}/{i + 1}' for i in t) + '\n' for t in f)


def write_ply(path, mesh):
    v, n, uv, f = mesh
    with open(path, 'w') as o:
        o.write('ply\nformat ascii 1.0\ncomment stand-in written by scripts/corpus_check.py\n')
        o.write(f'element vertex {len(v)}\n')
        o.write(''.join(f'property float {c}\n' for c in ('x', 'y', 'z', 'nx', 'ny', 'nz', 'u', 'v')))
        o.write(f'element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n')
        for p, q, t in zip(v, n, uv):
            o.write(' '.join(f'{x:.6f}' for x in (*p, *q, *t)) + '\n')
        o.writelines(f'3 {a} {b} {c}\n' for a, b, c in f)


def serialized_shape(name, mesh):
    v, n, uv, f = mesh
    body = struct.pack('<I', 0x0001 | 0x0002 | 0x1000) + name.encode() + b'\0'
    body += struct.pack('<QQ', len(v), len(f))
    for arr in (v, n, uv):
        flat = [c for x in arr for c in x]
        body += struct.pack(f'<{len(flat)}f', *flat)
    flat = [i for t in f for i in t]
    body += struct.pack(f'<{len(flat)}I', *flat)
    return struct.pack('<HH', 0x041C, 4) + zlib.compress(body)


def write_serialized(path, count):
    out, offsets = b'', []
    for k in range(count):
        offsets.append(len(out))
        out += serialized_shape(f'standin{k}', quad_mesh() if k == 0 else sphere_mesh())
    with open(path, 'wb') as o:
        o.write(out + struct.pack(f'<{len(offsets)}QI', *offsets, len(offsets)))


def standin_image(name, w=64, h=32):
    import numpy as np
    low = os.path.basename(name).lower()
    y, x = np.mgrid[0:h, 0:w].astype(np.float32)
    if 'normal' in low:
        img = np.stack([0.5 + 0.1 * np.sin(x / 3), 0.5 + 0.1 * np.cos(y / 3), np.ones_like(x)], -1)
    elif any(k in low for k in ('mask', 'opacity', 'alpha', 'rough', 'bump', 'height')):
        g = 0.25 + 0.5 * (((x // 8) + (y // 8)) % 2)
        img = np.stack([g, g, g], -1)
    else:
        img = np.stack([0.2 + 0.6 * x / (w - 1), 0.2 + 0.6 * y / (h - 1),
                        0.5 + 0.3 * np.sin(x / 5) * np.cos(y / 4)], -1)
    return np.ascontiguousarray(img.astype(np.float32))


def write_image(path, name):
    import imageio.v3 as iio
    import numpy as np
    img = standin_image(name)
    ext = os.path.splitext(path)[1].lower()
    if ext in ('.exr', '.hdr'):
        import mitsuba as mi
        if mi.variant() is None:
            mi.set_variant('scalar_rgb')
        mi.Bitmap(img).write(path)
    else:
        iio.imwrite(path, (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8),
                    extension=ext if ext != '.jpg' else '.jpeg')


def write_vol(path, n=16):
    """A Mitsuba .vol grid (version 3, float32, 1 channel) over the unit box:
    a smooth blob."""
    data = []
    for z in range(n):
        for y in range(n):
            for x in range(n):
                px, py, pz = [(c + 0.5) / n - 0.5 for c in (x, y, z)]
                data.append(max(0.0, 1.0 - 4 * (px * px + py * py + pz * pz)))
    with open(path, 'wb') as o:
        o.write(b'VOL' + bytes([3]) + struct.pack('<i', 1) + struct.pack('<iii', n, n, n))
        o.write(struct.pack('<i', 1) + struct.pack('<6f', 0, 0, 0, 1, 1, 1))
        o.write(struct.pack(f'<{len(data)}f', *data))


def same_name_in_repo(rel, ref):
    """A corpus file of the same name in the same repository (e.g. the
    Cornell box meshes that several folders of mitsuba-data hold)."""
    repo = rel.split(os.sep)[0]
    base = os.path.basename(ref)
    for d, _, files in os.walk(os.path.join(CORPUS, repo)):
        if base in files:
            return os.path.join(d, base)
    return None


def make_standin(path, name, serialized_count, twin=None):
    ext = os.path.splitext(path)[1].lower()
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if twin:
        shutil.copyfile(twin, path)
    elif ext == '.obj':
        write_obj(path, mesh_for(name))
    elif ext == '.ply':
        write_ply(path, mesh_for(name))
    elif ext == '.serialized':
        write_serialized(path, serialized_count)
    elif ext in ('.exr', '.png', '.jpg', '.jpeg', '.bmp', '.tga', '.hdr'):
        write_image(path, name)
    elif ext == '.vol':
        write_vol(path)
    elif ext == '.spd':
        with open(path, 'w') as o:
            o.write('400 0.5\n550 0.7\n700 0.9\n')
    else:
        return False
    return True


def resolve(ref, scene_dir, paths):
    cands = [os.path.join(scene_dir, ref)] + [os.path.join(scene_dir, p, ref) for p in paths]
    return next((c for c in cands if os.path.exists(c)), None)


# --------------------------------------------------------------------------
# Work copies


def scale_films(text, defaults, res):
    """Scale the literal or $default width/height inside every <film> so that
    the larger side is at most res. Returns the new text and the defaults
    to override."""
    overrides = {}

    def fix(m):
        block = m.group(0)
        dims = {}
        for k in ('width', 'height'):
            mm = re.search(r'name\s*=\s*"%s"\s+value\s*=\s*"([^"]+)"' % k, block)
            if mm:
                dims[k] = mm.group(1)
        vals = {}
        for k, v in dims.items():
            vv = subst(v, defaults)
            try:
                vals[k] = int(vv)
            except ValueError:
                return block
        w, h = vals.get('width', 768), vals.get('height', 576)
        s = min(1.0, res / max(w, h))
        nw, nh = max(1, round(w * s)), max(1, round(h * s))
        for k, nv in (('width', nw), ('height', nh)):
            if k not in dims:
                # the default film is 768 x 576: add the size explicitly
                block = re.sub(r'(<film[^>]*?)(/?)>', lambda q: q.group(1) + '>' + (
                    f'<integer name="{k}" value="{nv}"/>' + ('</film>' if q.group(2) else '')),
                    block, count=1)
                continue
            v = dims[k]
            if v.startswith('$'):
                overrides[v[1:]] = str(nv)
            else:
                block = re.sub(r'(name\s*=\s*"%s"\s+value\s*=\s*")[^"]+(")' % k,
                               lambda q: q.group(1) + str(nv) + q.group(2), block, count=1)
        return block

    text = re.sub(r'<film\b.*?</film>|<film\b[^>]*/>', fix, text, flags=re.S)
    return text, overrides


def prepare(args):
    for name in ('pristine', 'small'):
        d = os.path.join(OUT, name)
        if os.path.exists(d):
            shutil.rmtree(d)
        shutil.copytree(CORPUS, d)
    files = corpus_files()
    roots = root_scenes(files)
    if args.only:
        roots = [r for r in roots if any(o in r for o in args.only)]
    info = {}
    for rel in roots:
        closure, defaults, refs, paths = asset_refs(rel)
        sdir = os.path.join(CORPUS, os.path.dirname(rel))
        counts = shape_indices(closure)
        for pth in paths:
            for name in ('pristine', 'small'):
                os.makedirs(os.path.join(OUT, name, os.path.dirname(rel), pth), exist_ok=True)
        standins, missing = [], []
        for ref in refs:
            if '$' in ref:
                continue
            if resolve(ref, sdir, paths):
                continue
            ok = True
            for name in ('pristine', 'small'):
                target = os.path.join(OUT, name, os.path.dirname(rel), ref)
                if os.path.exists(target):
                    continue
                ok = make_standin(target, ref, max(counts.get(ref, 0) + 1, 8),
                                  same_name_in_repo(rel, ref)) and ok
            (standins if ok else missing).append(ref)
        # reduce films in the small copy (every file of the closure)
        overrides = {}
        for r, text in closure:
            new, ov = scale_films(text, defaults, args.res)
            overrides.update(ov)
            if new != text:
                with open(os.path.join(OUT, 'small', r), 'w') as o:
                    o.write(new)
        info[rel] = {'standins': sorted(set(standins)), 'missing': sorted(set(missing)),
                     'defines': overrides}
    return roots, info


# --------------------------------------------------------------------------
# Renders


def first_error(text):
    lines = [l.strip() for l in text.splitlines() if l.strip()]
    for l in lines:
        if l.startswith('error') or 'Error' in l or 'error:' in l:
            return l
    return lines[-1] if lines else '(no message)'


def run(cmd, timeout, env=None):
    t = time.perf_counter()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout, env=env)
        return p.returncode, p.stdout, p.stderr, time.perf_counter() - t
    except subprocess.TimeoutExpired:
        return -1, '', f'timeout after {timeout} s', time.perf_counter() - t


def penumbra_load(args, rel):
    scene = os.path.join(OUT, 'pristine', rel)
    rc, out, err, dt = run([args.penumbra, 'params', scene], args.timeout)
    return rc == 0, ('' if rc == 0 else first_error(err + out)), dt


def penumbra_render(args, rel, defines, seed, path):
    scene = os.path.join(OUT, 'small', rel)
    cmd = [args.penumbra, 'render', scene, '-o', path, '--spp', str(args.spp), '--seed', str(seed), '-q']
    for k, v in defines.items():
        cmd += ['-D', f'{k}={v}']
    rc, out, err, dt = run(cmd, args.timeout)
    return rc == 0, ('' if rc == 0 else first_error(err + out)), dt


MITSUBA_CHILD = r'''
import sys, json, os
import numpy as np
import mitsuba as mi
variant, scene, spp, prefix, defines = sys.argv[1], sys.argv[2], int(sys.argv[3]), sys.argv[4], json.loads(sys.argv[5])
integrator = json.loads(sys.argv[7])
mi.set_variant(variant)
os.chdir(os.path.dirname(scene))
sc = mi.load_file(scene, **defines)
integrator = mi.load_dict(integrator) if integrator else None
for k, seed in enumerate(json.loads(sys.argv[6])):
    img = np.array(mi.render(sc, spp=spp, seed=seed, integrator=integrator), dtype=np.float32)
    np.save(f"{prefix}_mi{k}.npy", img)
print("OK", img.shape)
'''


def mitsuba_render(args, rel, defines, prefix):
    scene = os.path.join(OUT, 'small', rel)
    env = dict(os.environ)
    env.setdefault('DRJIT_LIBLLVM_PATH', '/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1')
    rc, out, err, dt = run([sys.executable, '-c', MITSUBA_CHILD, args.variant, scene,
                            str(args.spp), prefix, json.dumps(defines), json.dumps(MITSUBA_SEEDS),
                            json.dumps(MITSUBA_INTEGRATOR.get(rel, (None, ''))[0])],
                           args.timeout, env)
    if rc == 0:
        return True, '', dt
    lines = [l.strip() for l in (err + out).splitlines() if l.strip()]
    msg = next((l for l in reversed(lines) if 'Error' in l or 'error' in l or 'Exception' in l),
               lines[-1] if lines else '(no message)')
    return False, msg, dt


def read_exr(path):
    import mitsuba as mi
    if mi.variant() is None:
        mi.set_variant('scalar_rgb')
    import numpy as np
    return np.array(mi.Bitmap(path), dtype=np.float64)


def blocks(img):
    import numpy as np
    h, w = img.shape[:2]
    b = BLOCK if min(h, w) >= 4 * BLOCK else 1
    h2, w2 = h // b * b, w // b * b
    x = img[:h2, :w2].reshape(h2 // b, b, w2 // b, b, -1).mean(axis=(1, 3))
    return x


def compare(pe, mi):
    """pe, mi: lists of SEEDS images each (H, W, C)."""
    import numpy as np
    P = np.stack([np.nan_to_num(blocks(x[..., :3])) for x in pe])
    M = np.stack([np.nan_to_num(blocks(x[..., :3])) for x in mi])
    n = len(pe)
    pm, mm = P.mean(0), M.mean(0)
    var = P.var(0, ddof=1) / n + M.var(0, ddof=1) / len(mi)
    diff = np.abs(pm - mm)
    tiny = 1e-6 * (np.abs(mm) + 1e-6)
    t = np.where(var > 0, diff / np.sqrt(np.maximum(var, 1e-300)), np.where(diff <= tiny, 0.0, np.inf))
    frac = float(np.mean(t > T_OUT))
    ip, im = P.mean(axis=(1, 2, 3)), M.mean(axis=(1, 2, 3))
    se = math.sqrt(ip.var(ddof=1) / n + im.var(ddof=1) / len(mi))
    dm = abs(ip.mean() - im.mean())
    z_mean = dm / se if se > 0 else (0.0 if dm <= 1e-9 else math.inf)
    rel = float(np.linalg.norm(pm - mm) / max(np.linalg.norm(mm), 1e-12))
    return {'frac_out': frac, 'z_mean': float(z_mean), 'rel_l2': rel,
            'mean_penumbra': float(ip.mean()), 'mean_mitsuba': float(im.mean()),
            'match': bool((frac < FRAC_MATCH and z_mean < Z_MEAN) or rel < REL_MATCH)}


def check_scene(args, rel, meta):
    res = {'scene': rel, **meta}
    tag = re.sub(r'[^A-Za-z0-9]+', '_', rel)
    prefix = os.path.join(OUT, 'img', tag)
    os.makedirs(os.path.dirname(prefix), exist_ok=True)
    ok, err, dt = penumbra_load(args, rel)
    res['penumbra_load'] = ok
    res['penumbra_error'] = err
    mok, merr, mdt = mitsuba_render(args, rel, meta['defines'], prefix)
    res['mitsuba_ok'] = mok
    res['mitsuba_error'] = merr
    res['mitsuba_s'] = mdt
    if not ok:
        res['outcome'] = 'refused' if mok else 'mitsuba-fails'
        return res
    imgs = []
    for seed in range(SEEDS):
        path = f'{prefix}_pe{seed}.exr'
        rok, rerr, rdt = penumbra_render(args, rel, meta['defines'], seed, path)
        res['penumbra_s'] = res.get('penumbra_s', 0) + rdt
        if not rok:
            res['penumbra_error'] = rerr
            res['outcome'] = 'render-error' if mok else 'mitsuba-fails'
            return res
        imgs.append(read_exr(path))
    if not mok:
        res['outcome'] = 'mitsuba-fails'
        return res
    import numpy as np
    mi_imgs = [np.load(f'{prefix}_mi{s}.npy').astype(np.float64) for s in range(SEEDS)]
    if imgs[0].shape[:2] != mi_imgs[0].shape[:2]:
        res['outcome'] = 'differs'
        res['note'] = f'image size {imgs[0].shape} vs Mitsuba {mi_imgs[0].shape}'
        return res
    res['channels'] = [imgs[0].shape[-1], mi_imgs[0].shape[-1]]
    if rel in MITSUBA_INTEGRATOR:
        res['note'] = MITSUBA_INTEGRATOR[rel][1]
    res.update(compare(imgs, mi_imgs))
    res['outcome'] = 'match' if res['match'] else 'differs'
    if res['match'] and (res['rel_l2'] > NOISY or max(res['mean_mitsuba'], res['mean_penumbra']) < 1e-6):
        # the noise hides any difference (or the image is black): no verdict
        res['outcome'] = 'inconclusive'
    return res


# --------------------------------------------------------------------------
# Report


def cause_of(err):
    """A short cause for grouping refusals."""
    m = re.search(r"(unknown|not implemented|not supported|unsupported)[^:;]*?'([^']+)'", err)
    if m:
        return f"{m.group(1)} '{m.group(2)}'"
    for pat, name in ((r'cannot decode image', 'image format'), (r'not found', 'file not found'),
                      (r'does not know parameter|unknown parameter|not a parameter', 'parameter')):
        if re.search(pat, err):
            return name
    return re.sub(r'^.*?:\d+: ', '', err)[:80]


def write_doc(results, args):
    groups = {}
    for r in results:
        groups.setdefault(r['outcome'], []).append(r)
    n = len(results)
    rendered = [r for r in results if r['outcome'] != 'mitsuba-fails']
    loads = [r for r in rendered if r['penumbra_load']]
    lines = ['# Public Mitsuba scenes: do they load unchanged and render like Mitsuba?', '',
             'Generated by `scripts/corpus_check.py` (a development tool: it needs Mitsuba 3, '
             'which CI does not have). The scenes are public files fetched unchanged into '
             '`scenes/corpus/` (provenance and licences in `scenes/corpus/SOURCES.md`); '
             'binary assets that could not be fetched as text are replaced by stand-ins '
             '(meshes, images, grids written by the script) in both renderers\' inputs, '
             'so a scene is judged on its XML and the plugins it uses.', '',
             f'Settings: {args.spp} samples per pixel per render, {SEEDS} seeds per renderer, films '
             f'scaled to at most {args.res} pixels, Mitsuba 3 variant `{args.variant}`. '
             f'A scene matches when fewer than {FRAC_MATCH:.0%} of its {BLOCK}x{BLOCK}-pixel block '
             f'values differ by more than {T_OUT:g} standard errors and the image means agree '
             f'within {Z_MEAN:g} standard errors, or the block-wise relative L2 difference is '
             f'below {REL_MATCH} (see the script). "out" is that fraction, "z mean" the '
             f'difference of the image means in standard errors.', '',
             '## Counts', '',
             '| | scenes |', '|---|---|',
             f'| scene files tried | {n} |',
             f'| Mitsuba 3 fails (excluded) | {len(groups.get("mitsuba-fails", []))} |',
             f'| Mitsuba 3 renders | {len(rendered)} |',
             f'| of which Penumbra loads unchanged | {len(loads)} |',
             f'| of which match | {len(groups.get("match", []))} |',
             f'| of which inconclusive (noise dominates, or black) | {len(groups.get("inconclusive", []))} |',
             f'| of which differ | {len(groups.get("differs", []))} |',
             f'| of which Penumbra loads, fails to render | {len(groups.get("render-error", []))} |',
             f'| of which Penumbra refuses | {len(groups.get("refused", []))} |',
             f'| scenes using stand-in assets (of those Mitsuba renders) | '
             f'{sum(1 for r in rendered if r["standins"])} |', '']
    ref = groups.get('refused', []) + groups.get('render-error', [])
    if ref:
        lines += ['## Refusals by cause', '']
        by = {}
        for r in ref:
            by.setdefault(cause_of(r['penumbra_error']), []).append(r)
        lines += ['| cause | scenes | first error line (one example) |', '|---|---|---|']
        for c, rs in sorted(by.items(), key=lambda kv: -len(kv[1])):
            ex = rs[0]['penumbra_error'].replace('|', '\\|').replace(OUT + '/pristine/', '').replace(OUT + '/small/', '')
            lines.append(f'| {c} | {len(rs)} | `{ex}` |')
        lines.append('')
    lines += ['## Per scene', '',
              '| scene | outcome | out | z mean | rel. L2 | mean Penumbra / Mitsuba | stand-ins | Penumbra error / note |',
              '|---|---|---|---|---|---|---|---|']
    for r in results:
        fo = f"{r['frac_out']:.3f}" if 'frac_out' in r else ''
        z = f"{r['z_mean']:.1f}" if 'z_mean' in r else ''
        rl = f"{r['rel_l2']:.3f}" if 'rel_l2' in r else ''
        means = f"{r['mean_penumbra']:.4g} / {r['mean_mitsuba']:.4g}" if 'mean_penumbra' in r else ''
        st = len(r['standins'])
        note = r.get('penumbra_error') or r.get('note', '')
        if r['outcome'] == 'mitsuba-fails':
            note = 'Mitsuba: ' + r.get('mitsuba_error', '')
            if r.get('penumbra_error'):
                note += ' — Penumbra: ' + r['penumbra_error']
            elif r.get('penumbra_load'):
                note += ' — Penumbra: loads'
        note = note.replace(OUT + '/pristine/', '').replace(OUT + '/small/', '').replace('|', '\\|')
        lines.append(f"| `{r['scene']}` | {r['outcome']} | {fo} | {z} | {rl} | {means} | {st or ''} | {note} |")
    lines.append('')
    text = '\n'.join(lines).replace(ROOT + '/', '')
    # the hand-written analysis after the marker survives a new run
    notes = ''
    if os.path.exists(DOC):
        old = read(DOC)
        if NOTES_MARKER in old:
            notes = old[old.index(NOTES_MARKER):]
    with open(DOC, 'w') as o:
        o.write(text + '\n' + (notes or NOTES_MARKER + '\n'))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    tgt = os.environ.get('CARGO_TARGET_DIR', os.path.join(ROOT, 'target'))
    ap.add_argument('--penumbra', default=os.path.join(tgt, 'release', 'penumbra'))
    ap.add_argument('--spp', type=int, default=32)
    ap.add_argument('--res', type=int, default=96)
    ap.add_argument('--variant', default='scalar_rgb')
    ap.add_argument('--timeout', type=int, default=300)
    ap.add_argument('--only', action='append', help='substring of the scenes to check (repeatable)')
    ap.add_argument('--no-doc', action='store_true', help='do not write docs/corpus.md')
    # (--only merges its rows into the last results.json before writing the doc)
    ap.add_argument('--doc-only', action='store_true',
                    help='rewrite docs/corpus.md from out/corpus/results.json (no renders)')
    args = ap.parse_args()
    if args.doc_only:
        with open(os.path.join(OUT, 'results.json')) as f:
            write_doc(json.load(f), args)
        return
    roots, info = prepare(args)
    results = []
    for i, rel in enumerate(roots):
        r = check_scene(args, rel, info[rel])
        results.append(r)
        extra = (f" out={r['frac_out']:.3f} zmean={r['z_mean']:.1f} rel={r['rel_l2']:.3f}"
                 if 'rel_l2' in r else '')
        msg = r.get('penumbra_error') or (r.get('mitsuba_error') if r['outcome'] == 'mitsuba-fails' else '')
        print(f'[{i + 1}/{len(roots)}] {rel}: {r["outcome"]}{extra} {msg}', flush=True)
    path = os.path.join(OUT, 'results.json')
    if args.only and os.path.exists(path):
        # a partial run replaces its scenes' rows of the last full run
        with open(path) as f:
            old = {r['scene']: r for r in json.load(f)}
        old.update({r['scene']: r for r in results})
        results = [old[k] for k in sorted(old)]
    with open(path, 'w') as o:
        json.dump(results, o, indent=1, default=str)
    if not args.no_doc:
        write_doc(results, args)


if __name__ == '__main__':
    main()
