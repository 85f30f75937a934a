"""Qt widgets of the Inclinometer: they display what the core computed and do no maths."""
