"""The variants of the robust BLA method a user can ask for (``nlsid bla --method``).

Kept apart from the numerical code so that the command line can offer the choices without
loading numpy:

- ``frf``: the input is known exactly; G = mean over realizations of Y/U (Schoukens, Pintelon
  and Rolain 2012, Section 6.1.1).
- ``io``: noisy input, no reference; the ratio of the period-averaged output and input spectra per
  realization (errors-in-variables, same section).
- ``reference``: closed loop, both spectra projected on the reference r (G = S_YR / S_UR, the
  BLA under feedback, Eqs. 6-75 to 6-77).
- ``auto``: ``reference`` when the runs carry r, else ``io``.
"""

METHOD_CHOICES = ("auto", "frf", "io", "reference")
