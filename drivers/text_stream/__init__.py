"""The parts of the text-line driver (``text://``, :mod:`drivers.text_lines`), one job each.

- :mod:`.lexer`: what one line of text holds (numbers, a header, labelled readings) and what a
  column or label name means (channel and unit);
- :mod:`.layout`: which column is which and the units, decided from the lines seen while
  connecting;
- :mod:`.parser`: classified lines to sample records (a vectorised path for numeric rows);
- :mod:`.timeline`: device times from a time column or from the lines' arrival times, with gaps;
- the device itself (port, open, read) stays in :mod:`drivers.text_lines`.
"""
