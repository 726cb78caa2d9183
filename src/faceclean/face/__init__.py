"""Faces: the one FaceMesh (mesh.py) for the viewer, glTF and the loss's vertex pairs
(pairs.py); our stylised face (rig.py, parts.py)."""
