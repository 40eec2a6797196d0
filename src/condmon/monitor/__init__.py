"""(monitor: see the issues that introduce this stage.)"""
