"""The engine the integrators stand on: a vertex's shading and the lanes that trace waves of paths.

- `vertex.shade_vertex`: one vertex in float64, for every material, light and guide; the
  wavefront, the per-thread loop and the lanes' general kernel shade with it.
- `lanes` (Embree only; `render(path_loop="lanes")`, CLI `--path-loop lanes`): a wave's paths
  as float32 structure-of-arrays lanes; under triangle lights its diffuse vertices (textured or
  not) are shaded by a vectorised loop, its coats and metals by `listed.shade_listed` (which takes
  the diffuse ones too under a guide: the guide's mixture, roulette and gain), every other vertex
  by `shade_vertex`; in a pass that records (a guide's training) the listed kernel takes the
  diffuse vertices, and it and the general kernel write the records (`guiding.records`).
  The integrators reach it through `lanes.usable(ctx, record, ps)` and
  `lanes.run(ctx, buf, n, ps, stats, split, record)`, which trace a wave that a source started in a
  wave.WaveBuffers (splitting it by a splitting.SplitPlan) and leave each path's radiance and
  AOVs in it, as the other path loops do. `rows` declares the lanes' state, `sampling32`
  their float32 random numbers; `general` holds the kernel that shades the vertices of no class.

Nothing here imports tracer.integrators, tracer.gradient or a guide beyond its contract
(guiding.contract) and its records (guiding.records).
"""
