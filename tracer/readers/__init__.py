"""Scene readers: each turns its files into a tracer.scene.SceneSpec, which scene.build_scene makes
into a Scene. `obj` reads an OBJ and its MTL files (the fast reader is tracer.objread), `sidecar`
the JSON beside it; `text` holds what they share."""
