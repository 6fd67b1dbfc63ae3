#!/usr/bin/env python3
"""Regenerates the seed corpora of fuzz/corpus/ (committed; `make fuzz` does
not run this). Usage: fuzz/make_corpus.py [GLTF_SAMPLES_DIR]

  gltf/        tests/data scenes and the small glTF sample models, with their
               external buffers and small images embedded as data URIs (so a
               seed is one self-contained file); basic.gltf and env_map.gltf
               keep their external files, which the fuzzer's scratch directory
               provides. Larger images are pointed at checker.png.
  image/       one selector byte (see fuzz/fuzz_image.c) + a small image file
               of each format: the tests' PNG/HDR files and oiiotool-made ones.
  ktx2/        small KTX2 files (core/ktx2.c) of each 8-bit layout, with no,
               zlib and Zstandard supercompression (a hand-made frame of one
               raw block: Python has no zstd), an orientation key, and
               Basis Universal and block-compressed headers that are refused.
  cli/         one selector byte (see fuzz/fuzz_cli.c) + option text.
  checkpoint/  is written by build-fuzz/fuzz_checkpoint (DR_FUZZ_WRITE_SEED)
               plus hand-made variants.
"""
import base64, glob, json, os, shutil, struct, subprocess, sys, zlib

root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
out = os.path.join(root, "fuzz", "corpus")
samples = sys.argv[1] if len(sys.argv) > 1 else os.path.join(root, "..", "shared", "gltf-samples")
MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}


def write(sub, name, data):
    os.makedirs(os.path.join(out, sub), exist_ok=True)
    with open(os.path.join(out, sub, name), "wb") as f:
        f.write(data)


def embed(path):
    """A .gltf with every resolvable external uri turned into a data URI."""
    try:
        doc = json.load(open(path))
    except ValueError:   # the malformed-input cases stay as they are
        return open(path, "rb").read()
    d = os.path.dirname(path)
    for key in ("buffers", "images"):
        for item in doc.get(key, []):
            uri = item.get("uri")
            if not uri or uri.startswith("data:"):
                continue
            f = os.path.join(d, uri)
            if not os.path.exists(f):
                continue
            data = open(f, "rb").read()
            if key == "images" and len(data) > 16384:
                item["uri"] = "checker.png"
                continue
            mime = "application/octet-stream" if key == "buffers" else MIME.get(os.path.splitext(f)[1].lower(), "image/png")
            item["uri"] = "data:%s;base64,%s" % (mime, base64.b64encode(data).decode())
    return json.dumps(doc, separators=(",", ":")).encode()


# ---- gltf ----
for f in sorted(glob.glob(os.path.join(root, "tests/data/*/*.gltf")) +
                glob.glob(os.path.join(root, "tests/data/gltf/meshopt/*.gltf"))):   # (gltfpack's outputs)
    name = os.path.basename(f)
    keep = name in ("basic.gltf", "env_map.gltf")
    write("gltf", name, open(f, "rb").read() if keep else embed(f))
for f in sorted(glob.glob(os.path.join(root, "tests/data/*/*.glb")) +
                glob.glob(os.path.join(root, "tests/data/gltf/meshopt/*.glb"))):
    write("gltf", os.path.basename(f), open(f, "rb").read())
for f in sorted(glob.glob(os.path.join(samples, "*/glTF*/*.gl*"))):
    if os.path.getsize(f) > 65536:
        continue
    data = embed(f) if f.endswith(".gltf") else open(f, "rb").read()
    if len(data) <= 65536:
        write("gltf", "sample-" + os.path.basename(f), data)

# ---- image ----
HINTS = ["fuzz", "x.png", "x.jpg", "x.exr", "x.hdr", "x.tif", "x.bmp", "x.tga", "x.pfm", "x.ppm", "x.gif",
         "x.psd", "x.dds", "image/png", "x.dpx", "x.fits", "x.iff", "x.sgi", "x.rla", "x.ico", "x.webp", "x.jp2",
         "x.pnm", "x.heic", "x.cin", "x.pic"]
for f in ["tests/data/gltf/checker.png", "tests/data/gltf/mr.png", "tests/data/gltf/sky.hdr",
          "tests/data/cli/truncated.png", "tests/data/optimize/texture-true.png"]:
    data = open(os.path.join(root, f), "rb").read()
    ext = os.path.splitext(f)[1]
    write("image", os.path.basename(f), bytes([HINTS.index("x" + ext)]) + data)
if shutil.which("oiiotool"):
    tmp = os.path.join(out, ".tmp")
    os.makedirs(tmp, exist_ok=True)
    for ext, args in [("exr", ["-d", "half"]), ("tif", ["-d", "float"]), ("bmp", []), ("tga", []), ("pfm", []),
                      ("ppm", []), ("jpg", []), ("gif", []), ("hdr", []), ("png", ["-d", "uint16"]),
                      # the other readers a texture or target can reach by its magic bytes
                      ("dpx", []), ("fits", []), ("iff", []), ("sgi", []), ("rla", []), ("ico", []), ("webp", []),
                      ("jp2", []), ("pnm", []), ("heic", [])]:
        p = os.path.join(tmp, "s." + ext)
        r = subprocess.run(["oiiotool", "--pattern", "checker:width=2:height=2", "6x5", "3"] + args + ["-o", p],
                           stderr=subprocess.DEVNULL)
        if r.returncode != 0:   # no writer for this format in this OpenImageIO
            continue
        sel = HINTS.index("x." + ext)
        write("image", "small-%s.%s" % (args[1] if args else "8", ext), bytes([sel]) + open(p, "rb").read())
        write("image", "sniff-%s.%s" % (args[1] if args else "8", ext), bytes([0]) + open(p, "rb").read())
    shutil.rmtree(tmp)

# ---- ktx2 ----
def zstd_raw(data):
    """A Zstandard frame holding data in one raw block (single segment, 1-byte content size: <= 255 bytes)."""
    assert len(data) <= 255
    return (bytes([0x28, 0xB5, 0x2F, 0xFD, 0x20, len(data)]) + (1 | (len(data) << 3)).to_bytes(3, "little") +
            bytes(data))


def ktx2(vk, w, h, ch, scheme, orientation=None, faces=1):
    texels = bytes((x * 37 + y * 101 + c * 53) & 255 for y in range(h) for x in range(w) for c in range(ch))
    level = {0: texels, 2: zstd_raw(texels), 3: zlib.compress(texels)}.get(scheme, texels[:16])
    kvd = b""
    if orientation:
        kv = b"KTXorientation\0" + orientation.encode() + b"\0"
        kvd = struct.pack("<I", len(kv)) + kv
        kvd += bytes(-len(kvd) % 4)
    head = bytes([0xAB, 0x4B, 0x54, 0x58, 0x20, 0x32, 0x30, 0xBB, 0x0D, 0x0A, 0x1A, 0x0A])
    head += struct.pack("<9I", vk, 1, w, h, 0, 0, faces, 1, scheme)
    head += struct.pack("<4I2Q", 0, 0, 104 if kvd else 0, len(kvd), 0, 0)
    head += struct.pack("<3Q", 104 + len(kvd), len(level), len(texels))
    return head + kvd + level


for name, args in [("rgb8-zstd", (23, 8, 8, 3, 2)), ("rgb8-zlib", (23, 5, 3, 3, 3)), ("srgb8-raw", (29, 4, 4, 3, 0)),
                   ("bgra8-zstd", (44, 6, 4, 4, 2)), ("r8-raw", (9, 7, 3, 1, 0)), ("rg8-zlib", (22, 3, 9, 2, 3)),
                   ("rgba8-ru", (43, 4, 6, 4, 2, "ru")), ("bgr8-lu", (30, 5, 5, 3, 0, "lu")),
                   ("etc1s-basislz", (0, 4, 4, 3, 1)), ("bc7", (145, 4, 4, 3, 0)), ("cubemap", (37, 2, 2, 4, 0, None, 6))]:
    write("ktx2", name + ".ktx2", ktx2(*args))

# ---- cli ----
CLI = [
    (0, "64"), (0, "1e12"), (0, "-3"), (0, "99999999999999999999"), (0, " 12"),
    (1, "18446744073709551615"), (1, "18446744073709551616"), (1, "-1"),
    (2, "0.02"), (2, "1e-400"), (2, "nan"), (2, "inf"), (2, "0x1p-3"),
    (3, "640x480"), (3, "100000x100000"), (3, "0x0"), (3, "32768X1"), (3, "12x"),
    (4, "\x03100000"), (4, "\x04" + "1e9"), (4, "\x051x1"), (4, "\x01tape"), (4, "\x01nope"), (4, "\x02attached"),
    (4, "\x08" + "256"), (4, "\x07" + "0"),
    (5, "/materials/0/pbrMetallicRoughness/baseColorFactor\n/images/0"),
    (5, "/materials/textured/emissiveFactor"), (5, "/extensions/KHR_lights_punctual/lights/0/intensity"),
    (5, "/images/1\n/images/1"), (5, "/extensions/DR_environment/color"),
    (6, "/materials/0/pbrMetallicRoughness/baseColorFactor=0.5,0.5,0.5"),
    (6, "/materials/0/pbrMetallicRoughness/roughnessFactor=2"),
    (6, "/extensions/KHR_lights_punctual/lights/1/intensity=1e300"), (6, "/images/0=1"),
    (6, "/materials/0/emissiveFactor=1,2,3,4,5"),
    (7, "l2"), (7, "/materials/0/pbrMetallicRoughness/metallicFactor"), (7, "/materials/~1/x"),
    (8, "512M"), (8, "1.5G"), (8, "0"), (8, "7TB"),
]
for i, (sel, text) in enumerate(CLI):
    write("cli", "seed-%02d" % i, bytes([sel]) + text.encode("latin-1"))
print("corpus written to", out)
