"""Inverse rendering of an object's pose: recover the translation and
rotation of a mesh from one image of it under an environment map.

    python pose_object.py [--iterations 150] [--res 64] [--sppp 4] [--out DIR] [--check]

The scene is scenes/pose_object.xml (the job scenes/jobs/pose_object.toml
does the same with `penumbra optimize`): a small asymmetric mesh, shaded
flat, floating under the museum environment map. `pn.Pose` maps a latent
translation t and rotation vector r (radians, about the mesh's centroid)
onto its vertex positions; `pn.render_backward` gives the gradient with
respect to the positions and `pose.backprop` turns it into (dL/dt, dL/dr)
for Adam (the loop, shared with pose_camera.py, is in pose_demo.py). Under
a distant environment a flat facet's radiance does not change when it moves, so the translation gradient comes entirely from the
boundary term of primary visibility (the silhouette and the facet edges,
`sppp` edge samples per pixel): with --sppp 0 the object does not move
back. With --check the script exits with status 1 unless the translation
error is below --max-translation-error (default 0.02) and the rotation
error below --max-rotation-error (default 2 degrees).
"""

import sys

import pose_demo

if __name__ == "__main__":
    sys.exit(
        pose_demo.main(
            __doc__,
            "pose_object.xml",
            "object.vertex_positions",
            init_t=[0.12, -0.08, 0.1],
            init_r_deg=[4.0, -7.0, 3.0],
            iterations=150,
            max_rotation_error=2.0,
        )
    )
