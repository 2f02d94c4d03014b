"""Guideline facts the imaging domains (radiology_report, visual_diagnosis) grade by, written once.

Management of a nodule in a patient with a known primary cancer: Fleischner 2017 (MacMahon et al.,
Radiology 2017) excludes these patients; the nodule is followed within the cancer's staging and
surveillance imaging (e.g. NCCN Colon Cancer: chest CT at staging and surveillance).
"""

from __future__ import annotations

KNOWN_MALIGNANCY_MANAGEMENT = "oncologic staging follow-up"
KNOWN_MALIGNANCY_ALIASES = ["Fleischner not applicable (known malignancy)", "follow-up within the oncologic staging and surveillance protocol",
                            "Fleischner guidelines do not apply"]
KNOWN_MALIGNANCY_GUIDELINE = ("Fleischner Society 2017 (MacMahon et al., Radiology 2017;284:228-243), scope: excludes patients with "
                              "known malignancy; NCCN Guidelines Colon Cancer (staging and surveillance chest CT)")
