"""``fusiongs view``: a finished run in the browser (viser): its Gaussians as 3DGS viewers draw
``model.ply``, the fitted camera path with a frustum per frame, each frame blurry beside deblurred,
and fusiongs' own sharp render at any instant of the path.

``run`` reads and checks the run folder (no viser), ``geometry`` turns the PLY and the poses into
what the viewer draws (no viser), ``server`` builds the page.
"""
