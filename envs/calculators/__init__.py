"""Clinical scoring instruments as plain, typed functions returning :class:`ScoreResult`.

Every function validates its inputs with cheap checks (raising :class:`CalculatorInputError`,
a ``ValueError``, that names the argument and its valid range), computes the instrument per
its published source (cited in ``ScoreResult.reference``) and is documented in Google style
so that the tool framework (``envs.core.tools.ToolDefinition.from_function``) can expose it to
agents unchanged. ``CALCULATORS`` maps each function's name to the function.

See ``README.md`` in this package for the extension contract and ``docs/calculators.md`` for
the catalogue, the independent implementations each instrument is checked against, and the
benchmark.
"""

from __future__ import annotations

from typing import Callable

from ._core import CalculatorInputError, ScoreResult
from .apache import calculate_apache2
from .cardiology import (
    calculate_cha2ds2_vasc,
    calculate_has_bled,
    calculate_heart_score,
    calculate_map,
    calculate_qtc,
    calculate_timi_ua,
    calculate_wells_dvt,
)
from .chest_imaging import calculate_lung_rads, fleischner_recommendation
from .critical_care import (
    calculate_aa_gradient,
    calculate_gcs,
    calculate_news2,
    calculate_qsofa,
    calculate_shock_index,
    calculate_sirs,
    calculate_sofa,
)
from .emergency import (
    calculate_alvarado,
    calculate_centor,
    calculate_esi_level,
    calculate_ottawa_ankle,
    calculate_parkland,
    calculate_revised_trauma_score,
)
from .general import (
    calculate_anion_gap,
    calculate_bmi,
    calculate_corrected_calcium,
    calculate_corrected_sodium,
    calculate_serum_osmolality,
)
from .hepatology import calculate_child_pugh, calculate_glasgow_blatchford, calculate_meld_na
from .neurology import calculate_abcd2, calculate_nihss
from .obstetrics import calculate_apgar, calculate_biophysical_profile, calculate_bishop_score
from .psychiatry import (
    administer_audit_c,
    administer_cage,
    administer_epds,
    administer_gad7,
    administer_phq9,
    assess_suicide_risk,
    calculate_ciwa_ar,
)
from .pulmonary import (
    calculate_crb65,
    calculate_curb65,
    calculate_perc,
    calculate_pesi,
    calculate_spesi,
    calculate_wells_pe,
)
from .radiology import calculate_birads, calculate_tirads
from .renal import (
    calculate_bedside_schwartz,
    calculate_ckd_epi_2021,
    calculate_creatinine_clearance,
    calculate_fena,
    calculate_free_water_deficit,
)

CALCULATORS: dict[str, Callable[..., ScoreResult]] = {
    fn.__name__: fn
    for fn in (
        # critical care
        calculate_gcs,
        calculate_qsofa,
        calculate_sirs,
        calculate_news2,
        calculate_sofa,
        calculate_apache2,
        calculate_shock_index,
        calculate_aa_gradient,
        # pulmonary
        calculate_curb65,
        calculate_crb65,
        calculate_wells_pe,
        calculate_perc,
        calculate_pesi,
        calculate_spesi,
        # cardiology
        calculate_heart_score,
        calculate_timi_ua,
        calculate_cha2ds2_vasc,
        calculate_has_bled,
        calculate_wells_dvt,
        calculate_qtc,
        calculate_map,
        # hepatology / GI
        calculate_meld_na,
        calculate_child_pugh,
        calculate_glasgow_blatchford,
        # renal
        calculate_creatinine_clearance,
        calculate_ckd_epi_2021,
        calculate_bedside_schwartz,
        calculate_fena,
        calculate_free_water_deficit,
        # general
        calculate_bmi,
        calculate_anion_gap,
        calculate_corrected_calcium,
        calculate_corrected_sodium,
        calculate_serum_osmolality,
        # emergency
        calculate_esi_level,
        calculate_centor,
        calculate_revised_trauma_score,
        calculate_parkland,
        calculate_alvarado,
        calculate_ottawa_ankle,
        # neurology
        calculate_nihss,
        calculate_abcd2,
        # obstetrics
        calculate_bishop_score,
        calculate_apgar,
        calculate_biophysical_profile,
        # psychiatry
        administer_phq9,
        administer_gad7,
        assess_suicide_risk,
        administer_epds,
        administer_audit_c,
        administer_cage,
        calculate_ciwa_ar,
        # radiology
        calculate_tirads,
        calculate_birads,
        fleischner_recommendation,
        calculate_lung_rads,
    )
}

__all__ = ["CALCULATORS", "CalculatorInputError", "ScoreResult", *CALCULATORS]
