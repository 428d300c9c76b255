"""Decode an 8-bit, non-interlaced PNG with the standard library only
(zlib on the IDAT chunks, then the five PNG row filters), for the tests:
    python3 png_read.py FILE   prints "W H CHANNELS" then the argmax
                               pixel(s) of the first channel as "x,y ..."
Exit 1 when the file is not such a PNG."""
import struct
import sys
import zlib


CHANNELS = {0: 1, 2: 3, 6: 4}  # PNG colour type: grey, RGB, RGBA


def read_png(path, ctypes=(0, 2)):
    """raysweep's quick-looks: 8-bit grey or RGB only."""
    return decode_png(open(path, "rb").read(), ctypes)


def decode_png(data, ctypes):
    """(width, height, channels, rows of bytes) of an 8-bit, non-interlaced
    PNG whose colour type is one of ctypes (0 grey, 2 RGB, 6 RGBA)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG signature")
    pos, idat, ihdr = 8, b"", None
    while pos < len(data):
        n, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + n]
        if zlib.crc32(kind + body) != struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])[0]:
            raise ValueError("bad CRC in chunk %r" % kind)
        if kind == b"IHDR":
            ihdr = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat += body
        elif kind == b"IEND":
            break
        pos += 12 + n
    w, h, depth, ctype, _, _, interlace = ihdr
    if depth != 8 or interlace != 0 or ctype not in ctypes:
        raise ValueError("want 8-bit, non-interlaced, colour type in %s (got depth %d, type %d, interlace %d)" %
                         (ctypes, depth, ctype, interlace))
    ch = CHANNELS[ctype]
    raw, stride = zlib.decompress(idat), w * ch
    rows, prev = [], bytearray(stride)
    for y in range(h):
        f, line = raw[y * (stride + 1)], bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - ch] if i >= ch else 0
            b, c = prev[i], prev[i - ch] if i >= ch else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append(line)
        prev = line
    return w, h, ch, rows


if __name__ == "__main__":
    try:
        w, h, ch, rows = read_png(sys.argv[1])
    except Exception as e:  # noqa: BLE001 - any failure is "not a PNG"
        print("not a readable PNG: %s" % e)
        sys.exit(1)
    top = max(rows[y][x * ch] for y in range(h) for x in range(w))
    print(w, h, ch)
    print(" ".join("%d,%d" % (x, y) for y in range(h) for x in range(w) if rows[y][x * ch] == top))
