"""Documents the app writes: the calibration report (HTML or PDF) and the fault detector's
curves (PNG). Painted with Qt's QtGui (QPainter, QTextDocument, QPdfWriter), never its widgets:
the window and the command line both use them, and the command line never imports the GUI.
"""
