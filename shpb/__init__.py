"""shpb: the Split Hopkinson Pressure Bar experiment around the FDEM engine.

Geometries (shpb.geometry), loading (shpb.loading), parameters (shpb.parameters), one simulation
(shpb.simulate.simulate, also `python -m shpb simulate`), measured-record readers and reduction
(shpb.lab.records, shpb.lab.reduction).
"""
