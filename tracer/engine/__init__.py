"""The engine the integrators stand on: a vertex's shading and the lanes that trace waves of paths.

- `vertex.shade_vertex`: one vertex in float64, for every material, light and guide; the
  wavefront, the per-thread loop and the lanes' general kernel shade with it.
- `lanes` (Embree only; `render(path_loop="lanes")`, CLI `--path-loop lanes`): a wave's paths
  as float32 structure-of-arrays lanes; the vertices of its fast class (diffuse, untextured,
  under triangle lights) are shaded by a vectorised loop, every other one by `shade_vertex`.
  The integrators reach it through `lanes.usable(ctx, record, ps)` and
  `lanes.run(ctx, buf, n, ps, stats, split)`, which trace a wave that a source started in a
  wave.WaveBuffers (splitting it by a splitting.SplitPlan) and leave each path's radiance and
  AOVs in it, as the other path loops do. `rows` declares the lanes' state; `general` holds the
  kernel that shades the vertices outside the fast class.

Nothing here imports tracer.integrators, tracer.gradient or a guide beyond its contract.
"""
