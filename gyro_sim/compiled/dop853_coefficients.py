"""The Butcher tableau of DOP853, the 12-stage, 8th-order explicit Runge–Kutta method of Dormand & Prince
(E. Hairer, S. P. Nørsett, G. Wanner, *Solving Ordinary Differential Equations I*, 2nd ed., Springer 1993,
§II.10; the coefficients of their Fortran code DOP853), as data of the project: the lawson8 stepper
(``kernels.dop853_tableau``) is this method with integrating factors.

The values are those of SciPy's ``scipy/integrate/_ivp/dop853_coefficients.py`` (SciPy, BSD-3-Clause,
Copyright (c) 2001-2002 Enthought, Inc., 2003- SciPy Developers), written here as the shortest repr() of each
float64 SciPy parses, so they are the same bits (test/test_startup.py compares them with SciPy's private arrays
where SciPy has them). Only the 12 stages the method steps with: SciPy's extra stages 13–16, the error
estimators E3, E5 and the dense-output D are not used here. Generated; do not edit by hand.
"""

N_STAGES = 12

#: c_i, the nodes (i = 0 … 11)
C = (0.0,
     0.05260015195876773,
     0.0789002279381516,
     0.1183503419072274,
     0.2816496580927726,
     0.3333333333333333,
     0.25,
     0.3076923076923077,
     0.6512820512820513,
     0.6,
     0.8571428571428571,
     1.0)

#: b_j, the weights (j = 0 … 11)
B = (0.054293734116568765,
     0.0,
     0.0,
     0.0,
     0.0,
     4.450312892752409,
     1.8915178993145003,
     -5.801203960010585,
     0.3111643669578199,
     -0.1521609496625161,
     0.20136540080403034,
     0.04471061572777259)

#: row i of A: a_ij for j < i (the explicit method's strictly lower triangle; the zeros are SciPy's zeros)
A_ROWS = (
    (),
    (0.05260015195876773,),  # row 1
    (0.0197250569845379, 0.0591751709536137),  # row 2
    (0.02958758547680685, 0.0, 0.08876275643042054),  # row 3
    (0.2413651341592667, 0.0, -0.8845494793282861, 0.924834003261792),  # row 4
    (0.037037037037037035, 0.0, 0.0, 0.17082860872947386,  # row 5
     0.12546768756682242),
    (0.037109375, 0.0, 0.0, 0.17025221101954405,  # row 6
     0.06021653898045596, -0.017578125),
    (0.03709200011850479, 0.0, 0.0, 0.17038392571223998,  # row 7
     0.10726203044637328, -0.015319437748624402, 0.008273789163814023),
    (0.6241109587160757, 0.0, 0.0, -3.3608926294469414,  # row 8
     -0.868219346841726, 27.59209969944671, 20.154067550477894, -43.48988418106996),
    (0.47766253643826434, 0.0, 0.0, -2.4881146199716677,  # row 9
     -0.590290826836843, 21.230051448181193, 15.279233632882423, -33.28821096898486,
     -0.020331201708508627),
    (-0.9371424300859873, 0.0, 0.0, 5.186372428844064,  # row 10
     1.0914373489967295, -8.149787010746927, -18.52006565999696, 22.739487099350505,
     2.4936055526796523, -3.0467644718982196),
    (2.273310147516538, 0.0, 0.0, -10.53449546673725,  # row 11
     -2.0008720582248625, -17.9589318631188, 27.94888452941996, -2.8589982771350235,
     -8.87285693353063, 12.360567175794303, 0.6433927460157636),
)
