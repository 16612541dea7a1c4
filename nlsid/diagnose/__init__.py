"""``nlsid.diagnose(model, rec, ...)``: what a simulation model gets wrong on measured data, the cause,
the fix, the gain (a :class:`nlsid.stages.diagnose.DiagnosisResult`; arguments and example in
:func:`nlsid.stages.diagnose.diagnose` and ``docs/api.md``).

This package holds the method (evidence, hypotheses, verdict, gain: :mod:`nlsid.diagnose.diagnosis`)
and is itself the face's call: the public name ``nlsid.diagnose`` and this package are one object,
so that it stays the function whichever of the two Python imported first.
"""

from __future__ import annotations

import sys
import types


class _Stage(types.ModuleType):
    """This package, callable as :func:`nlsid.stages.diagnose.diagnose` (imported on the first call:
    the package stays as light as before)."""

    def __call__(self, *args, **kwargs):
        from nlsid.stages.diagnose import diagnose

        return diagnose(*args, **kwargs)

    @property
    def __signature__(self):
        import inspect

        from nlsid.stages.diagnose import diagnose

        return inspect.signature(diagnose)


sys.modules[__name__].__class__ = _Stage
