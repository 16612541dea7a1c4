"""The stage functions of the library's face (``nlsid.read``, ``nlsid.bla``, ...) and their result types:
each takes in-memory objects (or a path) and returns an object with its numbers as attributes,
``.summary()``, ``.write(path)`` and, where the stage draws, ``.plot()``. The command line calls these."""
