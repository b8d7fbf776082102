from test_srb import *
def test_dbg():
    import qpsolvers
    from charctl.experiments.srb.qp import reduced_problem, INF
    rng = np.random.default_rng(3)
    batch = random_batch(rng, 10)
    params = QPParams(mass=60.0, mu=1.0, torque_limit=30.0, torque_reg=1e-3)
    h,f,lb,ub,k,k0=reduced_problem(batch,params)
    x=qpsolvers.solve_qp(h[0],f[0],lb=lb[0],ub=np.where(ub[0]>=INF,np.inf,ub[0]),solver='daqp', verbose=True)
    print('x', x)
    assert 0
