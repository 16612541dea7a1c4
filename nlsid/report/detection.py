"""When a class of nonlinear distortion counts as *detected* on a report page.

A class of distortion is detected when its band-mean power stands more than :data:`DETECTED_DB`
= 3 dB above the noise on the same scale. Justification: without distortion a detection line holds
only noise, ``|Y(k)|^2`` is exponentially distributed around the noise variance, so the band mean
over L lines and M realizations has a relative standard deviation ``1/sqrt(L M)``, and the noise
estimate (P - 1 degrees of freedom per line) ``1/sqrt(L M (P - 1))``; with the smallest useful
experiment (L >= 10 lines, M = 2, P = 2) the ratio scatters by about 0.27 in linear terms (about
1 dB), so 3 dB (a factor 2) is more than three standard deviations. The single-input page
(:mod:`nlsid.report.render_bla`) and the frequency-response-matrix page
(:mod:`nlsid.report.render_frm`) use the same threshold.
"""

DETECTED_DB = 3.0
