"""nlsid: nonlinear system identification from measured data.

The library is the product; the command line is a thin layer over the stage functions named here
(``docs/api.md``)::

    import nlsid
    rec = nlsid.read("sample_data/stage.h5")       # a Recording
    b = nlsid.bla(rec)                              # a BlaResult: .levels, .summary(), .plot(), .write(path)

Names are loaded on first use, so ``import nlsid`` stays light (numpy, scipy and h5py are imported
by the stage that needs them).
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

#: public name -> module that defines it
_FACE = {
    "InputError": "nlsid.errors",
    "Recording": "nlsid.stages.recording",
    "read": "nlsid.stages.recording",
    "bla": "nlsid.stages.bla",
    "BlaResult": "nlsid.stages.bla",
    "fit_tf": "nlsid.stages.fit",
    "TransferFunctionFit": "nlsid.stages.fit",
    "fit_model": "nlsid.stages.fit",
    "ModelFit": "nlsid.stages.fit",
    "fit_pnlss": "nlsid.stages.pnlss",
    "PnlssResult": "nlsid.stages.pnlss",
    "hosidf": "nlsid.stages.hosidf",
    "HosidfResult": "nlsid.stages.hosidf",
    "design": "nlsid.stages.design",
    "Excitation": "nlsid.stages.design",
    "Model": "nlsid.stages.model",
    "diagnose": "nlsid.diagnose",
    "DiagnosisResult": "nlsid.stages.diagnose",
}

__all__ = ["__version__", *_FACE]


def __getattr__(name: str):
    module = _FACE.get(name)
    if module is None:
        raise AttributeError(f"module 'nlsid' has no attribute {name!r}")
    imported = importlib.import_module(module)
    # a name that is its own subpackage (nlsid.diagnose, callable) is the package itself
    value = imported if module == f"nlsid.{name}" else getattr(imported, name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
