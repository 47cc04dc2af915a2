#!/usr/bin/env python3
"""Prototype (numpy, per-pixel, B = 1) of FLR with a per-pixel choice of window
size, kept to guide the library implementation (README "Next").

    python3 tools/flr_scales_proto.py 6,12,20 0.5 FRAMES_DIR

For each σ in the list the per-pixel regression of the noisy light on the
standardised guides (normal, depth, AO by default; GU=n,d,a,al adds albedo) is
fitted with Gaussian moments. Each scale's MSE is estimated from moments only:
variance = residual variance · (Q+1) / N_eff (N_eff = 4πσ² for a full window;
the residual needs Σ y², a moment FLR does not keep yet), bias² of a larger
scale = mean over the smallest scale's window of its prediction's difference
from the smallest scale's, minus K × the variance difference. "soft" blends the
scales with weights 1/MSE. Prints PSNR per frame (the DATA.md protocol).

Measured 2026-11-22 (256×256, 1 spp): train scenes σ=12 alone 32.67 dB, soft
6/12/20 with K = 0.5: 33.00; test scenes (measured once, afterwards) 32.23 →
32.74, every scene +0.3…+0.75 dB.
"""
import sys, glob, os
import numpy as np
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from metrics_reference import layer, tonemap
from scipy.ndimage import gaussian_filter as gf
LW=np.array([0.2126,0.7152,0.0722])
def G(a,s):  # normalized-weight blur with zero border (mask handles)
    return gf(a, s, mode="constant", truncate=3.0)
def load(f):
    d={k:layer(f,k) for k in ["reference","albedo","noisy","normal","depth","ao"]}
    return d
def fit(X, Y, m, s, eps_mul=1e-3, eps_add=1e-2):
    # X: h,w,q standardized guides; Y: h,w,3; m mask. per-pixel weighted LS at scale s
    h,w,q=X.shape
    W=G(m,s)+1e-12
    mx=np.stack([G(m*X[...,i],s) for i in range(q)],-1)/W[...,None]
    my=np.stack([G(m*Y[...,c],s) for c in range(3)],-1)/W[...,None]
    C=np.empty((h,w,q,q)); B=np.empty((h,w,q,3))
    for i in range(q):
        for j in range(i,q):
            C[...,i,j]=C[...,j,i]=G(m*X[...,i]*X[...,j],s)/W-mx[...,i]*mx[...,j]
        for c in range(3):
            B[...,i,c]=G(m*X[...,i]*Y[...,c],s)/W-mx[...,i]*my[...,c]
    yl=Y@LW
    Eyy=G(m*yl*yl,s)/W - (my@LW)**2
    d=np.diagonal(C,axis1=-2,axis2=-1)
    A=C+np.eye(q)*(eps_mul*d[...,None,:]+eps_add)
    beta=np.linalg.solve(A,B)  # h,w,q,3
    a=my-np.einsum("hwq,hwqc->hwc",mx,beta)
    # residual variance (luminance) and N_eff
    bl=beta@LW
    rss=np.maximum(Eyy-np.einsum("hwq,hwq->hw",bl,B@LW),0)
    W2=gf(m, s/np.sqrt(2), mode="constant", truncate=3.0)/(4*np.pi*s*s)
    neff=W*W/np.maximum(W2,1e-12)
    return dict(a=a,beta=beta,mx=mx,C=C,rss=rss,neff=neff,W=W)
def pred(mod,X):
    return mod["a"]+np.einsum("hwq,hwqc->hwc",X,mod["beta"])
def psnr(est,d):
    R=d["albedo"]*d["reference"]; L=np.mean(R@LW)
    return -10*np.log10(((tonemap(d["albedo"]*est,L)-tonemap(R,L))**2).mean())
res={}
scales=[float(x) for x in sys.argv[1].split(",")] if len(sys.argv)>1 else [6,12,20]
K=float(sys.argv[2]) if len(sys.argv)>2 else 1.0
for f in sorted(glob.glob(sys.argv[3]+"/*.exr" if len(sys.argv)>3 else "/work/frames/train/*.exr")):
    d=load(f); n=os.path.basename(f)[:-4]
    Y=np.where(np.isfinite(d["noisy"]),d["noisy"],0)
    hh,ww=Y.shape[:2]
    parts={"n":d["normal"],"d":d["depth"].reshape(hh,ww,1),"a":d["ao"].reshape(hh,ww,1),"al":d["albedo"],"all":(d["albedo"]@LW).reshape(hh,ww,1),"p":layer(f,"position"),
           "xy":np.stack(np.meshgrid(np.arange(ww),np.arange(hh)),-1).astype(float)}
    g=np.concatenate([parts[k] for k in os.environ.get("GU","n,d,a").split(",")],-1)
    m=(np.abs(d["normal"]).sum(-1)>0).astype(float)
    mu=(g*m[...,None]).sum((0,1))/m.sum(); sd=np.sqrt(((g-mu)**2*m[...,None]).sum((0,1))/m.sum())+1e-6
    X=(g-mu)/sd*m[...,None]
    mods=[fit(X,Y,m,s) for s in scales]
    P=[np.maximum(pred(md,X),0) for md in mods]
    row={f"s{s:g}":psnr(p,d) for s,p in zip(scales,P)}
    q=X.shape[-1]+1
    # blend: walk from largest to smallest; each scale's MSE estimate
    # var_s = rss_s * q / neff_s ; bias_s^2 ~ max(d2(s, smallest) - (var_small - var_s), 0)
    var=[md["rss"]*q/md["neff"] for md in mods]
    s0=mods[0]
    Xt=np.concatenate([np.ones(X.shape[:2]+(1,)),X],-1)
    # second moment matrix of [1,x] at smallest scale window
    M=np.zeros(X.shape[:2]+(q,q)); M[...,0,0]=1; M[...,0,1:]=s0["mx"]; M[...,1:,0]=s0["mx"]
    M[...,1:,1:]=s0["C"]+np.einsum("hwi,hwj->hwij",s0["mx"],s0["mx"])
    mse=[var[0]]
    for k in range(1,len(mods)):
        da=(mods[k]["a"]-s0["a"])@LW; db=(mods[k]["beta"]-s0["beta"])@LW
        dv=np.concatenate([da[...,None],db],-1)
        d2=np.einsum("hwi,hwij,hwj->hw",dv,M,dv)
        b2=np.maximum(d2-K*np.maximum(var[0]-var[k],0),0)
        mse.append(b2+var[k])
    mse=np.stack(mse)
    BS=float(os.environ.get("BS","0")); PW=float(os.environ.get("PW","1"))
    if BS>0: mse=np.stack([G(x*m,BS)/np.maximum(G(m,BS),1e-12) for x in mse])
    wts=np.maximum(mse,1e-30)**-PW; 
    hard=np.take_along_axis(np.stack(P),mse.argmin(0)[None,...,None],0)[0]
    soft=(np.stack(P)*(wts/wts.sum(0))[...,None]).sum(0)
    row["hard"]=psnr(hard,d); row["soft"]=psnr(soft,d)
    for k,v in row.items(): res.setdefault(k,[]).append(v)
    print(n," ".join(f"{k}:{v:.2f}" for k,v in row.items()),flush=True)
print("mean"," ".join(f"{k}:{np.mean(v):.2f}" for k,v in res.items()))
