#!/usr/bin/env python3
"""Reads the VTK files of `sdem export --vtk DIR` (or `sdem run --vtk DIR`) with the official
VTK package (`pip install vtk`) and prints what it found, one line per item:

    collection grains.pvd 12                      # datasets listed
    dataset grains.pvd 3 0.25 2400 0 200 id,radius,mean_stress_c,...   # k, time, points, lines, polys, arrays
    values grains.pvd mean_stress_c 0.0012 ...    # cell array of frame N (--values), as decoded

Usage: check_vtk.py DIR [--values N]   (N: the frame whose cell arrays are printed in full; -1,
the default, the last). Exits non-zero if a file does not parse.
"""
import argparse
import os
import sys
import xml.etree.ElementTree as ET

import vtk
from vtk.util.numpy_support import vtk_to_numpy


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dir")
    ap.add_argument("--values", type=int, default=-1)
    args = ap.parse_args()
    for pvd in ("grains.pvd", "contacts.pvd", "boundary.pvd"):
        path = os.path.join(args.dir, pvd)
        if not os.path.exists(path):
            continue
        sets = ET.parse(path).getroot().find("Collection").findall("DataSet")
        print("collection", pvd, len(sets))
        wanted = args.values % len(sets) if sets else None
        for k, ds in enumerate(sets):
            reader = vtk.vtkXMLPolyDataReader()
            reader.SetFileName(os.path.join(args.dir, ds.get("file")))
            reader.Update()
            if reader.GetErrorCode() != 0:
                sys.exit(f"{ds.get('file')}: VTK reader error {reader.GetErrorCode()}")
            poly = reader.GetOutput()
            cd = poly.GetCellData()
            arrays = {}
            for a in range(cd.GetNumberOfArrays()):
                arr = cd.GetArray(a)
                arrays[arr.GetName()] = [arr.GetNumberOfComponents(), arr.GetNumberOfTuples()]
            names = [cd.GetArray(a).GetName() for a in range(cd.GetNumberOfArrays())]
            for name in names:
                if cd.GetArray(name).GetNumberOfTuples() != poly.GetNumberOfCells():
                    sys.exit(f"{ds.get('file')}: {name} has the wrong length")
            print("dataset", pvd, k, repr(float(ds.get("timestep"))), poly.GetNumberOfPoints(),
                  poly.GetNumberOfLines(), poly.GetNumberOfPolys(), ",".join(names))
            if k == wanted:
                if poly.GetNumberOfLines() > 0:
                    pts = vtk_to_numpy(poly.GetPoints().GetData())
                    lines = vtk_to_numpy(poly.GetLines().GetConnectivityArray())
                    offsets = vtk_to_numpy(poly.GetLines().GetOffsetsArray())
                    lengths = []
                    for a, b in zip(offsets[:-1], offsets[1:]):
                        p, q = pts[lines[a]], pts[lines[b - 1]]
                        lengths.append(float(((p - q) ** 2).sum() ** 0.5))
                    print("values", pvd, "segment_length", " ".join(repr(v) for v in lengths))
                for name in ("mean_stress_c", "normal_force", "tangential_force", "level", "id"):
                    arr = cd.GetArray(name)
                    if arr is not None:
                        print("values", pvd, name, " ".join(repr(float(v)) for v in vtk_to_numpy(arr)))


if __name__ == "__main__":
    main()
