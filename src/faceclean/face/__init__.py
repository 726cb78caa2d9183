"""Face meshes: the loss's vertices, the viewer's GLB, our stylised face."""
