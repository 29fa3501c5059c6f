"""Inverse rendering of a camera's pose: recover where the camera is and
where it looks from one image of a known scene.

    python pose_camera.py [--iterations 100] [--res 64] [--sppp 4] [--out DIR] [--check]

The scene is scenes/pose_camera.xml (the job scenes/jobs/pose_camera.toml
does the same with `penumbra optimize`): three boxes on a ground under the
museum environment map. `pn.Pose` maps a latent translation t and rotation
vector r (radians, about the camera's position) onto the sensor's
`sensor.to_world`; `pn.render_backward` gives the gradient with respect to
that matrix and `pose.backprop` turns it into (dL/dt, dL/dr) for Adam (the
loop, shared with pose_object.py, is in pose_demo.py). The
scene's surfaces are flat and diffuse under a distant environment, so a
pixel's radiance changes with the camera's position only where an edge
crosses it: the translation gradient comes entirely from the boundary term
of primary visibility (`sppp` edge samples per pixel), and with --sppp 0
the camera turns back but does not move. With --check the script exits
with status 1 unless the translation error is below --max-translation-error
(default 0.02) and the rotation error below --max-rotation-error (default
1 degree).
"""

import sys

import pose_demo

if __name__ == "__main__":
    sys.exit(
        pose_demo.main(
            __doc__,
            "pose_camera.xml",
            "sensor.to_world",
            init_t=[0.12, -0.08, 0.1],
            init_r_deg=[3.0, -6.0, 4.0],
            iterations=100,
            max_rotation_error=1.0,
        )
    )
