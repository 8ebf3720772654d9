"""mppid in rerun's 3D viewer: the live view (live.py), flight logs as .rrd (convert.py), the
layout (blueprint.py), what each LCM channel becomes in the scene (scene.py), and a headless
browser's screenshot of the view (browser.py). docs/view.md says why rerun."""
