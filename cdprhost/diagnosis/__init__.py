"""cdprhost.diagnosis"""
