"""Signal processing: the sine-series smoother of 003 §1.3 (``sine_series``), periodograms, amplitude
spectra and line detection of 003 §1.5 (``spectral``), and the two-pass polynomial/spline filter of 000
(``two_pass_filter``).
"""
