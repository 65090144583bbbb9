"""cdprhost.calibration.readers"""
