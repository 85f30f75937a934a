"""The presenter's per-view feeds: each takes what one view shows from the ring buffers,
once per frame, and only when its input changed (:mod:`app.gui.presenter` runs the frame).

=============  ==============================================================
``screen``     whether a view can be seen at all (hidden views do no work)
``frame``      one frame's bookkeeping: drew, pending, when something falls due
``level``      the bubble level (and the attitude for the 3D view and the arm)
``readouts``   the numeric readouts, the simulator truth, stale figures, a stored reading
``plots``      the live plots: rebuilds, samples appended onto the screen, scrolling
``errors``     the Filter dock's error table
=============  ==============================================================
"""
