"""Textile-lab units in SI (Kawabata 1980 reports gram-force and centimetres)."""
G_STANDARD = 9.80665                   # m/s^2
GF = G_STANDARD * 1e-3                 # N per gram-force
GF_PER_CM = GF / 1e-2                  # N/m per gf/cm (load per width)
GF_CM_PER_CM2 = GF * 1e-2 / 1e-4       # J/m^2 per gf cm/cm^2 (energy per area)
GF_CM2_PER_CM = GF * 1e-4 / 1e-2       # N m per gf cm^2/cm (bending rigidity)
