"""Read an AAMA DXF with ezdxf (an independent reader) and print what it holds, as JSON:
the layers, and per block its entities by type and layer, its closed polylines' vertex
counts by layer, its texts, and the INSERTs of the model space."""
import json
import sys

import ezdxf


def main(path):
    doc = ezdxf.readfile(path)
    out = {"layers": sorted(layer.dxf.name for layer in doc.layers), "blocks": {}, "inserts": []}
    for block in doc.blocks:
        if block.name.startswith("*"):
            continue
        info = {"entities": {}, "closed_polylines": {}, "texts": [], "lines": {}}
        for e in block:
            key = f"{e.dxftype()}@{e.dxf.layer}"
            info["entities"][key] = info["entities"].get(key, 0) + 1
            if e.dxftype() in ("POLYLINE", "LWPOLYLINE") and e.is_closed:
                points = list(e.points()) if e.dxftype() == "POLYLINE" else list(e.get_points("xy"))
                info["closed_polylines"].setdefault(e.dxf.layer, []).append(
                    [[float(p[0]), float(p[1])] for p in points])
            if e.dxftype() == "TEXT":
                info["texts"].append([e.dxf.layer, e.dxf.text])
            if e.dxftype() == "LINE":
                info["lines"].setdefault(e.dxf.layer, []).append(
                    [[e.dxf.start.x, e.dxf.start.y], [e.dxf.end.x, e.dxf.end.y]])
        out["blocks"][block.name] = info
    for e in doc.modelspace():
        if e.dxftype() == "INSERT":
            out["inserts"].append([e.dxf.name, e.dxf.insert.x, e.dxf.insert.y])
    json.dump(out, sys.stdout)


if __name__ == "__main__":
    main(sys.argv[1])
