"""The papers' published numbers, as data, for ``benchmarks/reproduce_papers.py``, ``docs/results.md`` and the
course (notebook 10, which reads them from the installed package).

Transcribed from text extractions of the five papers (cited by title and year with each table).  Every table cites
its paper, table number and page.  The Remote Sensing paper's extraction keeps page anchors
(``#page-N-0``, 0-based), so its pages are PDF pages; the other extractions carry no page marks, so only
the journal page range is given.  Where the extraction garbled or lost a number it is ``None`` and the
table's ``notes`` say what was printed; nothing is guessed.  Where a printed number is internally
inconsistent (e.g. a maximum below the RMSE) it is kept as printed and flagged in ``notes``.

Units: pixels for RMSE / dr_max (scanline errors), seconds for times (the authors' Intel Core i7-7500U
2.90 GHz laptop, five million SCPs per image), metres in Habib et al.
"""

from __future__ import annotations

PAPERS = {
    "mlp": {
        "cite": "Ahooei Nezhad, Valadan Zoej, Khoshelham, Ghorbanian, Farnaghi, Jamali, Youssefi, Gheisari "
                "(2024), Best Scanline Determination of Pushbroom Images for a Direct Object to Image Space "
                "Transformation Using Multilayer Perceptron, Remote Sensing 16(15), 2787",
        "file": "000_079d1f4e21c324c2.txt",
    },
    "lrm": {
        "cite": "Ahooei Nezhad, Valadan Zoej, Youssefi, Ghaderpour (2024), A Linear Regression Approach for "
                "Best Scanline Determination in the Object to Image Space Transformation Using Pushbroom "
                "Images, Sensors 24(17), 5594",
        "file": "001_adce85d80b7c445a.txt",
    },
    "bp": {
        "cite": "Yue, Sun, Xie, The remote sensing image geometrical model of BP neural network, ISPRS "
                "Archives (GF-2 imagery)",
        "file": "002_2e7456eeea287768.txt",
    },
    "bss2020": {
        "cite": "Ahooei Nezhad, Valadan Zoej, Jannati (2020), Accuracy improvement of best scanline search "
                "algorithms for ground to image transformation in pushbroom images (in Persian), Journal of "
                "Geospatial Information Technology 8(1), 23-38",
        "file": "003_18a093e668d76c99.txt",
    },
    "habib": {
        "cite": "Habib, Weshahy, El-Ghazaly, El-Shehaby (2018), Geometric Correction of High Resolution "
                "Satellite Imagery Using Hybrid Non-parametric Model",
        "file": "004_785a9adfc9d8b20a.txt",
    },
}

#: The Sensors paper renames the ten images (its Table 2); the Remote Sensing paper's ids are our presets.
LRM_IMAGE_TO_PRESET = {
    "SPI": "ISB", "MP": "PMA", "AP": "PAU", "JQB": "QII", "JS": "SJB", "AS": "SAN", "CS": "SCB",
    "BWV": "WBU", "SWV": "WSA", "SDWV": "WSU",
}

# ----------------------------------------------------------------------------------------------------------
# MLP paper (Remote Sensing 16:2787)
# ----------------------------------------------------------------------------------------------------------
MLP_TABLE3 = {
    "paper": "mlp",
    "table": "Table 3",
    "page": "PDF p. 9 (extraction anchor #page-8-0)",
    "title": "The results of ISB image analysis using different MLPs (five million SCPs)",
    "preset": "ISB",
    "columns": ("n_scops", "layers", "neurons", "rmse_px", "time_s", "dr_max_px", "n_parameters"),
    "rows": [
        (50, 1, 10, 0.06, 3.27, 0.15, 41),
        (100, 1, 10, 0.01, 3.40, 0.02, 41),
        (100, 1, 20, 0.05, 4.20, 0.17, 81),
        (300, 1, 10, 0.02, 3.90, 0.07, 41),
        (300, 1, 20, 0.02, 4.84, 0.06, 81),
        (300, 1, 30, 0.02, 5.62, 0.06, 121),
        (300, 1, 40, 0.02, 6.36, 0.08, 161),
        (300, 1, 50, 0.09, 7.75, 0.03, 201),
        (300, 2, 10, 0.06, 5.70, 0.37, 151),
        (300, 2, 20, 0.14, 19.63, 0.69, 501),
        (500, 1, 10, 0.03, 3.95, 0.09, 41),
        (500, 1, 20, 0.02, 4.69, 0.07, 81),
        (500, 1, 30, 0.001, 5.95, 0.003, 121),
        (500, 1, 40, 0.001, 6.64, 0.005, 161),
        (500, 1, 50, 0.002, 7.76, 0.01, 201),
        (500, 2, 10, 0.06, 5.80, 0.30, 151),
        (500, 2, 20, 0.05, 21.48, 0.15, 501),
        (500, 3, 10, 0.02, 8.47, 0.20, 261),
        (1000, 1, 10, 0.04, 4.04, 0.09, 41),
        (1000, 1, 20, 0.06, 5.17, 0.15, 81),
        (1000, 1, 30, 0.05, 6.81, 0.16, 121),
        (1000, 1, 40, 0.10, 8.04, 0.24, 161),
        (1000, 1, 50, 0.02, 9.72, 0.08, 201),
        (1000, 2, 10, 0.03, 6.86, 0.20, 151),
        (1000, 2, 20, 0.01, 26.40, 0.09, 501),
        (1000, 3, 10, 0.14, 10.23, 0.90, 261),
        (1000, 4, 10, 0.02, 17.83, 0.93, 371),
        (1000, 5, 10, 0.01, 26.53, 0.09, 481),
    ],
    "notes": [
        "The SCOP column is a merged cell printed once per group in the extraction (50 on row 1, 100 on row "
        "3, 300 on row 7, 500 on row 14, 1000 on row 23); groups were assigned by the (layers, neurons) "
        "sequence restarting at (1, 10): 50 -> 1 row, 100 -> 2, 300 -> 7, 500 -> 8, 1000 -> 10 rows.  The "
        "parameter counts (41 = 2*10+10+10+1 for one hidden layer of 10 on inputs (X, Y), 151 for two, ...) "
        "agree with every row.",
        "Row (300 SCOPs, 1 x 50): dr_max 0.03 < RMSE 0.09 is impossible (the maximum bounds the RMSE); "
        "printed so, probably swapped.",
    ],
}

MLP_TABLE4 = {
    "paper": "mlp",
    "table": "Table 4",
    "page": "PDF p. 14 (extraction anchor #page-13-0)",
    "title": "Proposed MLP vs NR, BWS, ANN-BSD and OGP-BSD (five million SCPs)",
    "columns": ("method", "rmse_px", "time_s", "dr_max_px"),
    "datasets": {
        "ISB": [
            ("nr", 5.840e-10, 511.919, 1.727e-9),
            ("bws", 0.57, 1490.505, 1.0),
            ("ann", 0.29, 3.295, 0.61),
            ("ogp", 0.29, 6.812, 0.57),
            ("mlp", 0.015, 3.29, 0.043),
        ],
    },
    "notes": [
        "Only the first dataset's block survived the extraction, without its dataset label; the two "
        "'Table 4. Cont.' parts (the other nine images) are empty.  It is the ISB image: its NR and BWS "
        "times (511.919 s, 1490.505 s) match the Sensors paper's Table 4 SPI (= ISB) row (512.00 s, "
        "1491.20 s).",
        "The same image in the Sensors paper's Table 4 has BWS RMSE 0.60 (here 0.57) and ANN/OGP RMSE 0.28 "
        "(here 0.29): the two papers do not print identical numbers for the same runs.",
    ],
}

# ----------------------------------------------------------------------------------------------------------
# LRM paper (Sensors 24:5594)
# ----------------------------------------------------------------------------------------------------------
LRM_TABLE3 = {
    "paper": "lrm",
    "table": "Table 3",
    "page": "Sec. 3 (the extraction has no page marks)",
    "title": "LRM-BSD for 10, 30, 50, 100 SCOPs and five million SCPs per image",
    "columns": ("image", "preset", "n_scops", "rmse_px", "time_s", "dr_max_px"),
    "rows": [
        ("SPI", "ISB", 10, 4.5e-9, 2.72, 7.4e-9), ("SPI", "ISB", 30, 4.0e-9, 2.37, 7.6e-9),
        ("SPI", "ISB", 50, 1.2e-9, 2.00, 2.7e-9), ("SPI", "ISB", 100, 4.0e-9, 2.02, 7.2e-9),
        ("MP", "PMA", 10, 3.1e-9, 2.10, 6.4e-9), ("MP", "PMA", 30, 2.3e-9, 2.29, 3.3e-9),
        ("MP", "PMA", 50, 2.3e-9, 2.13, 4.4e-9), ("MP", "PMA", 100, 4.8e-9, 2.25, 9.0e-9),
        ("AP", "PAU", 10, 1.5e-9, 2.48, 4.0e-9), ("AP", "PAU", 30, 2.1e-9, 2.25, 4.5e-9),
        ("AP", "PAU", 50, 2.9e-9, 2.40, 5.8e-9), ("AP", "PAU", 100, 1.7e-9, 2.68, 3.1e-9),
        ("JQB", "QII", 10, 7.0e-10, 2.52, 1.6e-9), ("JQB", "QII", 30, 4.4e-10, 2.25, 9.5e-10),
        ("JQB", "QII", 50, 5.9e-10, 3.16, 1.0e-9), ("JQB", "QII", 100, 2.6e-9, 2.75, 3.9e-9),
        ("JS", "SJB", 10, 8.8e-10, 3.11, 2.4e-9), ("JS", "SJB", 30, 2.0e-9, 2.60, 4.4e-9),
        ("JS", "SJB", 50, 9.9e-10, 2.28, 3.3e-9), ("JS", "SJB", 100, 2.1e-9, 2.63, 3.3e-9),
        ("AS", "SAN", 10, 5.7e-10, 2.49, 1.0e-9), ("AS", "SAN", 30, 3.1e-10, 2.31, 7.6e-10),
        ("AS", "SAN", 50, 1.8e-10, 2.34, 3.9e-10), ("AS", "SAN", 100, 1.6e-9, 2.82, 2.1e-9),
        ("CS", "SCB", 10, 1.7e-10, 2.60, 3.7e-10), ("CS", "SCB", 30, 2.8e-10, 2.36, 5.5e-10),
        ("CS", "SCB", 50, 2.8e-10, 2.42, 5.5e-10), ("CS", "SCB", 100, 6.0e-10, 2.09, 1.2e-9),
        ("BWV", "WBU", 10, 1.8e-9, 2.30, 4.3e-9), ("BWV", "WBU", 30, 9.8e-10, 2.41, 2.5e-9),
        ("BWV", "WBU", 50, 3.3e-9, 2.38, 5.5e-9), ("BWV", "WBU", 100, 3.9e-9, 2.50, 7.2e-9),
        ("SWV", "WSA", 10, 9.0e-10, 1.94, 1.7e-9), ("SWV", "WSA", 30, 3.2e-9, 1.95, 4.1e-9),
        ("SWV", "WSA", 50, 3.9e-9, 1.79, 7.3e-9), ("SWV", "WSA", 100, 3.0e-9, 1.93, 4.3e-9),
        ("SDWV", "WSU", 10, 1.0e-9, 2.29, 1.7e-9), ("SDWV", "WSU", 30, 2.6e-9, 1.95, 4.5e-9),
        ("SDWV", "WSU", 50, 1.1e-9, 1.95, 1.8e-9), ("SDWV", "WSU", 100, 1.4e-9, 2.03, 2.1e-9),
    ],
    "notes": [
        "Image ids are the Sensors paper's (its Table 2); the preset column maps them to the Remote Sensing "
        "paper's ids (same images, same order, same sizes).",
        "The text (Sec. 4) adds that the PRM (polynomial regression) gave 'the same accuracy' with "
        "higher-order coefficients close to zero; no PRM table is printed.",
    ],
}

LRM_TABLE4 = {
    "paper": "lrm",
    "table": "Table 4",
    "page": "Sec. 3 (the extraction has no page marks)",
    "title": "LRM-BSD vs NR, BWS, ANN-BSD and OGP-BSD (five million SCPs)",
    "columns": ("method", "rmse_px", "time_s", "dr_max_px", "n_scops"),
    "datasets": {
        "ISB": [("nr", 5.9e-10, 512.00, 1.73e-9, None), ("bws", 0.60, 1491.20, 1.0, None),
                ("ann", 0.28, 3.30, 0.61, 400), ("ogp", 0.28, 6.80, 0.57, 400), ("lrm", 1.2e-9, 2.00, 2.7e-9, 50)],
        "PMA": [("nr", 1.0e-9, 591.70, 2.6e-9, None), ("bws", 0.58, 1415.10, 1.0, None),
                ("ann", 0.30, 3.43, 0.67, 500), ("ogp", 0.30, 7.94, 0.67, 500), ("lrm", 2.3e-9, 2.29, 3.3e-9, 30)],
        "PAU": [("nr", 9.6e-10, 520.21, 1.2e-9, None), ("bws", 0.58, 1396.87, 1.0, None),
                ("ann", 0.30, 3.40, 0.67, 500), ("ogp", 0.30, 7.64, 0.77, 500), ("lrm", 1.5e-9, 2.48, 4.0e-9, 10)],
        "QII": [("nr", 4.4e-10, 425.94, 1.2e-9, None), ("bws", 0.58, 1324.22, 1.0, None),
                ("ann", 0.30, 3.81, 0.72, 500), ("ogp", 0.30, 7.84, 0.69, 500), ("lrm", 4.4e-10, 2.25, 9.5e-10, 30)],
        "SJB": [("nr", 6.2e-10, 484.48, 2.2e-9, None), ("bws", 0.58, 1355.63, 1.0, None),
                ("ann", 0.30, 3.77, 0.73, 500), ("ogp", 0.30, 9.96, 0.63, 1000), ("lrm", 8.8e-10, 3.11, 2.4e-9, 10)],
        "SAN": [("nr", 2.5e-10, 460.37, 6.2e-10, None), ("bws", 0.58, 1270.50, 1.0, None),
                ("ann", 0.29, 4.45, 0.58, 700), ("ogp", 0.31, 8.31, 0.81, 500), ("lrm", 1.8e-10, 2.34, 3.9e-10, 50)],
        "SCB": [("nr", 6.6e-10, 415.30, 2.4e-9, None), ("bws", 0.58, 890.40, 1.0, None),
                ("ann", 0.29, 3.39, 0.61, 400), ("ogp", 0.29, 7.07, 0.55, 200), ("lrm", 1.7e-10, 2.60, 3.7e-10, 10)],
        "WBU": [("nr", 1.2e-9, 477.54, 2.7e-9, None), ("bws", 0.56, 1376.80, 1.0, None),
                ("ann", 0.29, 3.57, 0.52, 400), ("ogp", 0.28, 7.97, 0.52, 400), ("lrm", 9.8e-10, 2.41, 2.5e-9, 30)],
        "WSA": [("nr", 9.9e-10, 475.13, 2.5e-9, None), ("bws", 0.57, 1250.78, 1.0, None),
                ("ann", 0.32, 3.31, 0.72, 500), ("ogp", 0.32, 7.80, 0.71, 500), ("lrm", 9.0e-10, 1.94, 1.7e-9, 10)],
        "WSU": [("nr", 3.9e-10, 490.56, 9.3e-10, None), ("bws", 0.57, 1285.10, 1.0, None),
                ("ann", 0.30, 3.71, 0.57, 500), ("ogp", 0.30, 8.80, 0.58, 500), ("lrm", 1.0e-9, 2.29, 1.7e-9, 10)],
    },
    "notes": [
        "Datasets renamed to our preset ids (SPI->ISB, MP->PMA, AP->PAU, JQB->QII, JS->SJB, AS->SAN, "
        "CS->SCB, BWV->WBU, SWV->WSA, SDWV->WSU).",
        "The LRM column repeats the best row of Table 3 per image (checked: all ten agree).",
        "'Number of SCOPs' is '-' for NR and BWS (no training).",
    ],
}

# ----------------------------------------------------------------------------------------------------------
# Persian paper (J. Geospatial Information Technology 8(1), 2020): sub-pixel interpolation of SS / BWS
# ----------------------------------------------------------------------------------------------------------
_BSS_COLUMNS = ("method", "space", "max_ce_per_point", "rmse_px", "time_s", "rmse_interp_px", "time_interp_s")
BSS2020_TABLE1 = {
    "paper": "bss2020",
    "table": "Table 1",
    "page": "pp. 23-38 (the extraction has no page marks)",
    "title": "Sensors and data",
    "rows": [
        {"sensor": "SPOT-3 (HRV)", "rows_x_cols": "6000 x 6000", "focal_length_m": 1.0820, "ccd_um": 13,
         "n_real_points": 35, "n_simulated_points": 35},
        {"sensor": "RapidEye (MS)", "rows_x_cols": "12000 x 11980", "focal_length_m": 0.6330, "ccd_um": 6.5,
         "n_real_points": 32, "n_simulated_points": 32},
    ],
    "notes": ["Persian decimal comma: '۱,۰۸۲۰' is 1.0820."],
}

BSS2020_TABLE2 = {
    "paper": "bss2020",
    "table": "Table 2",
    "page": "pp. 23-38 (the extraction has no page marks)",
    "title": "Proposed methods and four existing ones, 35 simulated points, SPOT-3 (6000 x 6000)",
    "columns": _BSS_COLUMNS,
    "rows": [
        ("bws", "image", 15, 0.30, 1.88, 5.498e-8, 1.96),
        ("ss", "image", 6000, 0.30, 65.90, 5.498e-8, 66.79),
        ("nr", "image", 4, 4.690e-9, 1.87, None, None),
        ("hybrid", "object", 3, 1.123e-7, 3.16, None, None),
    ],
    "notes": [
        "Column order in the extraction (right-to-left table): search procedure, max CE evaluations per "
        "point, RMSE of the proposed (interpolated) variant, RMSE of the original method, time of the "
        "proposed variant, time of the original, equations, search space, method.  'rmse_interp_px' / "
        "'time_interp_s' are the paper's proposed variants (ss-interp, bws-interp, eq. 4); NR and the "
        "hybrid method have no proposed variant ('-').",
        "The time is for the 35 points (seconds, as printed).  'ss' is 'sequential search in image space', "
        "'hybrid' the object-space hybrid method (affine, projective and collinearity equations).",
    ],
}

BSS2020_TABLE3 = {
    "paper": "bss2020",
    "table": "Table 3",
    "page": "pp. 23-38 (the extraction has no page marks)",
    "title": "Same, 35 real control points, SPOT-3 (not reproducible: real GCP errors)",
    "columns": _BSS_COLUMNS,
    "rows": [
        ("bws", "image", 15, 0.87, 1.91, 0.71, 1.78),
        ("ss", "image", 6000, 0.76, 69.30, 0.65, 69.81),
        ("nr", "image", 4, 0.64, 1.78, None, None),
        ("hybrid", "object", 3, 0.64, 3.53, None, None),
    ],
    "notes": ["Real points: the RMSE includes the GCPs' own errors, which no simulation reproduces."],
}

BSS2020_TABLE4 = {
    "paper": "bss2020",
    "table": "Table 4",
    "page": "pp. 23-38 (the extraction has no page marks)",
    "title": "Proposed methods and four existing ones, 32 simulated points, RapidEye (12000 x 11980)",
    "columns": _BSS_COLUMNS,
    "rows": [
        ("bws", "image", 14, 0.29, 1.82, 7.635e-8, 1.71),
        ("ss", "image", 1200, 0.29, 748.64, 7.635e-8, 747.84),
        ("nr", "image", 4, None, 1.95, None, None),
        ("hybrid", "object", 3, 1e-4, 9.12, None, None),
    ],
    "notes": [
        "NR RMSE garbled by the right-to-left extraction: printed '۵e-۲,۰۹' (the tokens 5, e-, 2,09); "
        "probably 2.09e-5 but not used here.",
        "SS max CE printed 1200 for a 12000-row image, while Table 2 prints 6000 for the 6000-row SPOT-3 "
        "image (a full scan); 1200 is kept as printed (possibly a dropped zero).",
        "Hybrid RMSE printed as 0.0001.",
    ],
}

BSS2020_TABLE5 = {
    "paper": "bss2020",
    "table": "Table 5",
    "page": "pp. 23-38 (the extraction has no page marks)",
    "title": "Same, 32 real control points, RapidEye (not reproducible: real GCP errors)",
    "columns": _BSS_COLUMNS,
    "rows": [
        ("bws", "image", 14, 1.02, 1.70, 0.91, 1.72),
        ("ss", "image", 1200, 1.02, 759.93, 0.91, 759.04),
        ("nr", "image", 4, 0.90, 1.74, None, None),
        ("hybrid", "object", 3, 0.90, 8.68, None, None),
    ],
    "notes": ["The header prints 'RMSE of the proposed method' twice; by position the second is the original "
              "method's RMSE, as in Tables 2-4."],
}

# ----------------------------------------------------------------------------------------------------------
# BP network paper (Yue, Sun, Xie; GF-2): (x, y, Z) -> (X, Y), errors in pixels
# ----------------------------------------------------------------------------------------------------------
_BP_COLUMNS = (
    "nodes", "ctl_x_max", "ctl_x_rms", "ctl_y_max", "ctl_y_rms", "ctl_plan_max", "ctl_plan_rms",
    "chk_x_max", "chk_x_rms", "chk_y_max", "chk_y_rms", "chk_plan_max", "chk_plan_rms",
)
_BP_NOTE_PLAN = (
    "As printed, the 'planarity' RMS is often below the X and Y RMS (e.g. 2 nodes: 1.39, 1.03, planarity "
    "0.87), which sqrt(RMS_X^2 + RMS_Y^2) cannot be; the paper does not define 'planarity'."
)
BP_TABLE2 = {
    "paper": "bp", "table": "Table 2", "page": "Sec. 3.2 (no page marks)",
    "title": "BP network IGM accuracy, dataset 1 (Songshan, mountain), terrain-independent: 10x10x5 control "
             "grid, 5x5x5 check grid",
    "columns": _BP_COLUMNS,
    "rows": [
        (2, 3.35, 1.39, 3.94, 1.03, 5.10, 0.87, 3.17, 1.43, 2.96, 0.99, 4.86, 0.87),
        (3, 1.25, 1.01, 1.76, 0.45, 2.71, 0.51, 2.72, 1.61, 1.67, 0.64, 5.74, 1.01),
        (4, 0.13, 0.04, 0.08, 0.04, 0.13, 0.02, 0.56, 0.20, 0.30, 0.11, 0.56, 0.11),
        (5, 0.09, 0.04, 0.08, 0.04, 0.10, 0.02, 0.10, 0.05, 0.11, 0.04, 0.14, 0.03),
        (6, 0.09, 0.04, 0.08, 0.04, 0.11, 0.02, 0.08, 0.04, 0.08, 0.03, 0.09, 0.02),
        (7, 0.07, 0.04, 0.09, 0.04, 0.10, 0.02, 0.07, 0.04, 0.07, 0.03, 0.09, 0.02),
    ],
    "notes": [
        "A garbled duplicate of the caption sits under the table in the extraction.", _BP_NOTE_PLAN,
        "The prose (Sec. 3.2) says the max error above 4 nodes is 0.04 px and 'stable ... 0.02 pixel', which "
        "matches the RMS columns, not the Max columns (0.07-0.14 px); the tables are used, not the prose.",
    ],
}
BP_TABLE3 = {
    "paper": "bp", "table": "Table 3", "page": "Sec. 3.2 (no page marks)",
    "title": "Same, dataset 2 (Baguacheng, hill), terrain-independent",
    "columns": _BP_COLUMNS,
    "rows": [
        (2, 5.16, 1.95, 7.07, 1.91, 7.93, 1.33, 5.09, 1.95, 6.90, 2.08, 7.81, 1.44),
        (3, 3.51, 1.25, 2.25, 0.88, 3.59, 0.74, 2.18, 1.24, 3.37, 1.23, 5.43, 0.70),
        (4, 0.22, 0.07, 0.20, 0.07, 0.28, 0.05, 0.21, 0.08, 0.14, 0.06, 0.24, 0.05),
        (5, 0.33, 0.10, 0.24, 0.08, 0.38, 0.06, 0.19, 0.06, 0.13, 0.06, 0.20, 0.04),
        (6, 0.29, 0.09, 0.30, 0.08, 0.33, 0.05, 0.09, 0.04, 0.09, 0.04, 0.11, 0.02),
        (7, 0.09, 0.04, 0.10, 0.04, 0.11, 0.02, 0.08, 0.04, 0.08, 0.04, 0.11, 0.02),
    ],
    "notes": [_BP_NOTE_PLAN],
}
BP_TABLE4 = {
    "paper": "bp", "table": "Table 4", "page": "Sec. 3.2 (no page marks)",
    "title": "Same, dataset 3 (Paris, city), terrain-independent",
    "columns": _BP_COLUMNS,
    "rows": [
        (2, 7.93, 2.28, 12.97, 3.34, 14.35, 2.21, 7.27, 2.29, 8.52, 3.24, 9.95, 2.05),
        (3, 3.06, 1.71, 5.92, 1.43, 7.42, 1.15, 1.82, 1.08, 2.87, 1.26, 3.84, 0.82),
        (4, 0.13, 0.05, 0.15, 0.05, 0.17, 0.03, 0.17, 0.08, 0.22, 0.06, 0.22, 0.05),
        (5, 0.11, 0.04, 0.12, 0.04, 0.15, 0.02, 0.07, 0.04, 0.09, 0.04, 0.12, 0.02),
        (6, 0.09, 0.04, 0.12, 0.04, 0.13, 0.02, 0.07, 0.04, 0.11, 0.04, 0.11, 0.02),
        (7, 0.08, 0.04, 0.10, 0.04, 0.11, 0.02, 0.07, 0.04, 0.09, 0.04, 0.11, 0.02),
    ],
    "notes": [_BP_NOTE_PLAN],
}
BP_TABLE5 = {
    "paper": "bp", "table": "Table 5", "page": "Sec. 3.2 (no page marks)",
    "title": "Terrain-dependent BP network IGM accuracy, dataset 1: 100 real GCPs, 22 check points",
    "columns": _BP_COLUMNS,
    "rows": [
        (1, 79.56, 42.58, 49.25, 20.08, 380.91, 43.87, 68.59, 23.61, 54.25, 17.67, 87.45, 25.87),
        (2, 67.91, 43.68, 50.61, 19.90, 399.47, 45.09, 5.50, 12.62, 20.28, 6.92, 31.31, 8.80),
        (3, 81.49, 42.78, 47.86, 19.73, 387.45, 44.44, 50.15, 19.75, 39.67, 16.30, 63.95, 20.61),
        (4, 99.73, 38.06, 73.31, 15.62, 281.96, 34.48, 19.69, 21.22, 12.85, 6.39, 55.18, 14.81),
        (5, 78.55, 29.09, 60.23, 7.15, 299.51, 28.93, 90.16, 40.69, 105.67, 40.68, 107.34, 29.46),
        (6, 52.23, 13.35, 51.54, 6.65, 79.12, 12.47, 9.41, 5.88, 3.39, 2.93, 10.49, 3.06),
        (7, 60.89, 45.18, 32.19, 16.50, 413.02, 43.76, 73.10, 44.19, 38.32, 13.79, 117.12, 39.98),
    ],
    "notes": [
        "The node-number column was lost in the extraction (seven rows).  Nodes 1-7 are inferred: the text "
        "says the errors are smallest at 6 nodes (row 6: 10.49 / 3.06 px) and quotes the range 10.49-117.12 "
        "px max and 3.06-39.98 px RMS, which are rows 6 and 7.",
        "Row 2 check X: max 5.50 < RMS 12.62 is impossible as printed.",
        "Real GCPs: not reproducible by simulation.",
    ],
}
BP_TABLE6 = {
    "paper": "bp", "table": "Table 6", "page": "Sec. 3.2 (no page marks)",
    "title": "RFM accuracy of all the datasets",
    "columns": ("test",) + _BP_COLUMNS[1:],
    "rows": [
        ("dataset 1 terrain-independent", 0.07, 0.03, 0.09, 0.04, 1.16, 0.05, 0.07, 0.03, 0.08, 0.03, 0.24, 0.04),
        ("dataset 2 terrain-independent", 0.07, 0.03, 0.11, 0.05, 1.51, 0.05, 0.06, 0.03, 0.11, 0.05, 0.40, 0.06),
        ("dataset 3 terrain-independent", 0.06, 0.03, 0.13, 0.05, 1.54, 0.06, 0.06, 0.03, 0.10, 0.03, 0.37, 0.05),
        ("dataset 1 terrain-dependent", 101.95, 12.57, 33.11, 5.22, 20749.01, 13.61, 11.44, 4.35, 3.85, 3.87,
         339.06, 5.82),
    ],
    "notes": [
        "Terrain-dependent check Y: max 3.85 < RMS 3.87, impossible as printed (rounding at best).",
    ],
}

# ----------------------------------------------------------------------------------------------------------
# Habib et al. 2018: QuickBird, 9 GPS check points, metres
# ----------------------------------------------------------------------------------------------------------
HABIB_TABLE2 = {
    "paper": "habib",
    "table": "Table 2",
    "page": "'Analysis and Results' (no page marks)",
    "title": "Check point errors (m) of the conventional RFM (572 AGE-matched GCPs) and the hybrid "
             "ANN + RFM (756 gridded GCPs from a 4-hidden-layer, 32-neuron MLP), QuickBird 0.62 m",
    "columns": ("point", "rfm_err_x", "rfm_err_y", "hybrid_err_x", "hybrid_err_y"),
    "rows": [
        (14, 1.678, -0.061, 0.205, -0.261), (16, -0.733, 0.251, 0.264, -0.622),
        (18, -0.928, 2.150, 0.235, -0.470), (20, -0.348, 0.865, -1.610, -0.839),
        (22, 0.981, 0.139, -1.392, -0.578), (32, 0.705, 0.442, 0.503, 1.616),
        (34, -1.998, -0.155, 1.167, -0.079), (36, -1.600, -1.607, -0.306, -0.398),
        (39, 1.125, 0.890, -0.622, -0.489),
    ],
    "mean": (-0.124, 0.324, -0.173, -0.236),
    "rms": (1.223, 0.949, 0.851, 0.685),
    "total_rmse_m": {"rfm": 1.55, "hybrid": 1.09},
    "total_rmse_px": {"rfm": 2.5, "hybrid": 1.76},
    "notes": [
        "Real GPS check points on real imagery: not reproducible by simulation; kept for reference.",
        "The row labelled RMS is the standard deviation about the mean (population): recomputed from the "
        "nine residuals it is 1.224 / 0.949 / 0.851 / 0.686 m, while the RMS about zero is 1.230 / 1.003 / "
        "0.869 / 0.725 m.  The text's totals 1.55 m and 1.09 m are sqrt(sx^2 + sy^2) of those deviations; "
        "the true total RMS errors are 1.59 m and 1.13 m.",
    ],
}

ALL_TABLES = {
    "mlp_table3": MLP_TABLE3, "mlp_table4": MLP_TABLE4, "lrm_table3": LRM_TABLE3, "lrm_table4": LRM_TABLE4,
    "bss2020_table1": BSS2020_TABLE1, "bss2020_table2": BSS2020_TABLE2, "bss2020_table3": BSS2020_TABLE3,
    "bss2020_table4": BSS2020_TABLE4, "bss2020_table5": BSS2020_TABLE5, "bp_table2": BP_TABLE2,
    "bp_table3": BP_TABLE3, "bp_table4": BP_TABLE4, "bp_table5": BP_TABLE5, "bp_table6": BP_TABLE6,
    "habib_table2": HABIB_TABLE2,
}
