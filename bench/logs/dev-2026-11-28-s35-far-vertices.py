import sys, numpy as np
from scipy.spatial import cKDTree
def load_ply(p):
    b=open(p,'rb').read(); h=b.index(b'end_header\n')+11; head=b[:h].decode()
    nv=int(head.split('element vertex ')[1].split()[0])
    props=[l.split()[-1] for l in head.split('element vertex')[1].split('element face')[0].splitlines() if l.startswith('property')]
    v=np.frombuffer(b[h:h+nv*4*len(props)],dtype='<f4').reshape(nv,len(props))[:,:3]
    return v.astype(np.float64)
xyz=np.fromfile(sys.argv[1],dtype='<f4').reshape(-1,3).astype(np.float64)
r=float(sys.argv[2]); V=load_ply(sys.argv[3])
t=cKDTree(xyz)
d,i=t.query(V); d/=r
nb=np.array([len(x)-1 for x in t.query_ball_point(xyz,4*r)])
print(f"vertices {len(V)} particles {len(xyz)} p50 {np.percentile(d,50):.3f} p99 {np.percentile(d,99):.3f} max {d.max():.3f}")
far=d>1.0
print(f"beyond 1.0 r: {far.sum()} ({100*far.mean():.2f}%)")
n=nb[i]
for lo,hi in [(0,5),(5,25),(25,60),(60,120),(120,10**9)]:
    m=(n>=lo)&(n<hi)
    print(f" nearest particle with {lo}-{hi} neighbours in 4r: vertices {m.sum()}, far {(far&m).sum()}, far share of them {100*(far&m).sum()/max(1,m.sum()):.1f}%")
# particle-count of the connected cluster of the nearest particle (linked within 2r)
import scipy.sparse as sp, scipy.sparse.csgraph as cg
pairs=t.query_pairs(2*r,output_type='ndarray')
A=sp.coo_matrix((np.ones(len(pairs)),(pairs[:,0],pairs[:,1])),shape=(len(xyz),len(xyz)))
nc,lab=cg.connected_components(A,directed=False)
size=np.bincount(lab)[lab]
s=size[i]
for lo,hi in [(1,2),(2,10),(10,100),(100,10**9)]:
    m=(s>=lo)&(s<hi)
    print(f" cluster of {lo}-{hi} particles: vertices {m.sum()}, far {(far&m).sum()}")
