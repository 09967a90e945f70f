"""Independent reader for talus's tests: read a LAS/LAZ file with laspy and print JSON.

Usage: read_extra_bytes.py FILE [N]

Prints the header facts (point count, format, version, scales, offsets, bounds, WKT bit,
(E)VLR ids, GeoTIFF ProjectedCSTypeGeoKey), the extra-bytes dimensions (name, numpy type,
description) as laspy decodes them from the Extra Bytes VLR, and the first N values (default 10)
of x, y, z and of every extra dimension. NaN is printed as null (JSON has no NaN), and every
float as its shortest round-trip string (repr) so that the reader parses the exact binary value
(serde_json's default float parsing can be one ulp off).
"""

import json
import math
import sys

import laspy


def clean(v):
    v = v.item() if hasattr(v, "item") else v
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else None
    return v


def main():
    path = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 10
    las = laspy.read(path)
    h = las.header
    fmt = las.point_format
    extra = []
    for name in fmt.extra_dimension_names:
        dim = fmt.dimension_by_name(name)
        extra.append({"name": name, "type": str(dim.dtype), "description": dim.description})
    epsg = None
    vlrs = []
    for v in list(h.vlrs) + list(las.evlrs or []):
        vlrs.append([v.user_id, v.record_id])
        if v.record_id == 34735:
            for k in v.geo_keys:
                if k.id == 3072 and k.tiff_tag_location == 0:
                    epsg = k.value_offset
    out = {
        "point_count": int(h.point_count),
        "point_format": fmt.id,
        "version": f"{h.version.major}.{h.version.minor}",
        "scales": [clean(float(s)) for s in h.scales],
        "offsets": [clean(float(o)) for o in h.offsets],
        "mins": [clean(float(m)) for m in h.mins],
        "maxs": [clean(float(m)) for m in h.maxs],
        "wkt_bit": bool(h.global_encoding.wkt),
        "vlrs": vlrs,
        "epsg": epsg,
        "extra_dims": extra,
        "x": [clean(v) for v in las.x[:n]],
        "y": [clean(v) for v in las.y[:n]],
        "z": [clean(v) for v in las.z[:n]],
        "extra": {e["name"]: [clean(v) for v in las[e["name"]][:n]] for e in extra},
    }
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main()
