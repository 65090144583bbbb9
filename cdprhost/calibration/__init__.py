"""cdprhost.calibration"""
