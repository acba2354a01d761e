"""Any result of the workflows as the command line prints it: `summary(result)`."""

from __future__ import annotations

from functools import singledispatch

from cpas_ocp.campaign.dispersion_study import DispersionModel
from cpas_ocp.campaign.peak_load_study import StageLoads
from cpas_ocp.discrepancy.diagnosis import Diagnosis
from cpas_ocp.discrepancy.discovery import Discovery
from cpas_ocp.discrepancy.wind_evidence import WindEvidence
from cpas_ocp.inference.model_comparison import Comparison
from cpas_ocp.inference.process_intensity import IntensityChoice
from cpas_ocp.inference.result_claim import Claim
from cpas_ocp.inference.whatif import WhatIfResult
from cpas_ocp.io.import_reports import ImportSummary
from cpas_ocp.reports.campaign_text import dispersion_model_text, stage_loads_text
from cpas_ocp.reports.discrepancy_text import (
    comparison_text,
    diagnosis_text,
    discovery_text,
    wind_evidence_text,
)
from cpas_ocp.reports.fit_text import claim_text, intensity_text, whatif_text
from cpas_ocp.reports.import_text import import_text


@singledispatch
def summary(result: object) -> str:
    """The terminal text of `result`: a diagnosis, a discovery, a comparison, a claim, a
    what-if study, a wind intensity choice, an import, a dispersion model or a stage's
    peak loads (the interface's own results have a `summary()` method)."""
    own = getattr(result, "summary", None)
    if callable(own):
        return own()
    raise TypeError(f"no summary of a {type(result).__name__}")


for _kind, _text in ((Diagnosis, diagnosis_text), (Discovery, discovery_text),
                     (Comparison, comparison_text), (Claim, claim_text),
                     (WhatIfResult, whatif_text), (IntensityChoice, intensity_text),
                     (ImportSummary, import_text), (DispersionModel, dispersion_model_text),
                     (StageLoads, stage_loads_text), (WindEvidence, wind_evidence_text)):
    summary.register(_kind, _text)
