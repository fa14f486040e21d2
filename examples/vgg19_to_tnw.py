#!/usr/bin/env python3
"""Converts torchvision VGG-19 weights to terrainnet's .tnw layout (optional; not needed at run time).

usage: python3 examples/vgg19_to_tnw.py vgg19.pth vgg19.tnw
       python3 examples/vgg19_to_tnw.py --download vgg19.tnw   (torchvision fetches the ImageNet weights)

Input: a state dict of torchvision.models.vgg19 (keys features.N.weight / features.N.bias; a
state dict of just the `features` module, keys N.weight, also works). Output: the 32 tensors
conv<g>_<i>.weight (Cout x Cin x 3 x 3) and conv<g>_<i>.bias (Cout) in the order conv1_1 .. conv5_4,
float32, in the .tnw format documented in terrainnet.h (@@optim): "TNW1", u32 version 1, u32 count,
per tensor u16 name length, name, u8 ndim, u8 flags (1 = buffer), u32 dims, float32 data, then the
CRC-32 of everything before it. Needs only numpy and torch (for reading the .pth file).
"""
import struct
import sys
import zlib

GROUPS = [2, 2, 4, 4, 4]
# indices of the conv layers inside torchvision's vgg19().features
FEATURE_INDEX = [0, 2, 5, 7, 10, 12, 14, 16, 19, 21, 23, 25, 28, 30, 32, 34]


def layer_names():
    return ["conv%d_%d" % (g + 1, i + 1) for g, n in enumerate(GROUPS) for i in range(n)]


def convert(state, out_path):
    import numpy as np
    prefix = "features." if any(k.startswith("features.") for k in state) else ""
    tensors = []
    for name, idx in zip(layer_names(), FEATURE_INDEX):
        for part in ("weight", "bias"):
            key = "%s%d.%s" % (prefix, idx, part)
            if key not in state:
                sys.exit("missing %s in the state dict (is it torchvision vgg19?)" % key)
            arr = np.ascontiguousarray(state[key].detach().cpu().numpy().astype("<f4"))
            tensors.append(("%s.%s" % (name, part), arr))
    body = bytearray(b"TNW1" + struct.pack("<II", 1, len(tensors)))
    for name, arr in tensors:
        nb = name.encode()
        body += struct.pack("<H", len(nb)) + nb + struct.pack("<BB", arr.ndim, 1)
        body += struct.pack("<%dI" % arr.ndim, *arr.shape) + arr.tobytes()
    body += struct.pack("<I", zlib.crc32(bytes(body)) & 0xFFFFFFFF)
    with open(out_path, "wb") as f:
        f.write(body)
    print("wrote %s: %d tensors, %.1f MB" % (out_path, len(tensors), len(body) / 1e6))


def main():
    import torch
    if len(sys.argv) == 3 and sys.argv[1] == "--download":
        import torchvision
        state = torchvision.models.vgg19(weights="IMAGENET1K_V1").state_dict()
        convert(state, sys.argv[2])
    elif len(sys.argv) == 3:
        convert(torch.load(sys.argv[1], map_location="cpu"), sys.argv[2])
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
